"""Stop training when it diverges, before a bad checkpoint is written.

Three checks, each raising :class:`NonFiniteLossError` that names the
iteration, the bad terms or tensors, and the last good checkpoint (the
target of ``last_checkpoint``, which
:class:`~.safe_checkpoint_hook.SafeCheckpointHook` updates only after a
checkpoint is verified and which therefore still exists):

* ``after_train_iter``: every loss term of the iteration, and the
  gradient norm the optimiser wrapper logs when it clips gradients
  (``train/grad_norm``; skipped for ``AmpOptimWrapper``, whose loss
  scaler expects and skips infinite gradients). By then the optimiser has
  stepped, but this hook runs at ``BELOW_NORMAL``, after ``LoggerHook``
  and before ``CheckpointHook`` (``VERY_LOW``), so nothing is saved.
* ``before_save_checkpoint``: every floating tensor of the model's state
  dict and of the optimiser state must be finite. A step can explode the
  weights while its own loss is still finite (the loss is computed before
  the step); this catches it before the checkpoint is written, so the last
  good one is never rotated away.
"""
import os.path as osp
from typing import Dict, List, Optional

import torch
from mmdet3d.registry import HOOKS
from mmengine.dist import all_reduce, get_world_size
from mmengine.hooks import Hook


class NonFiniteLossError(FloatingPointError):
    """Training diverged; raised by :class:`NonFiniteLossHook`."""


def non_finite_terms(outputs: Optional[dict]) -> Dict[str, float]:
    """Loss terms of ``outputs`` that are NaN or infinite.

    Args:
        outputs (dict, optional): The ``log_vars`` of ``train_step``: the
            total ``loss`` and every term whose name contains ``loss``
            (scalars or tensors; a tensor counts if any element is bad).

    Returns:
        dict[str, float]: ``{name: value}`` of the bad terms (the first bad
        element of a tensor), in the order of ``outputs`` but with the total
        ``loss`` last.
    """
    bad = {}
    for name, value in (outputs or {}).items():
        if 'loss' not in name:
            continue
        value = torch.as_tensor(value).detach()
        if not value.is_floating_point():
            continue
        finite = torch.isfinite(value)
        if not bool(finite.all()):
            bad[name] = float(value[~finite].flatten()[0])
    # The terms first: the total 'loss' is bad because one of them is.
    return dict(sorted(bad.items(), key=lambda item: item[0] == 'loss'))


def non_finite_tensors(tree, prefix: str = '') -> List[str]:
    """Floating tensors holding NaN / inf in a nested dict / list.

    Args:
        tree: A state dict, optimiser state, or any nesting of dicts,
            lists and tensors.
        prefix (str): Name of ``tree``. Defaults to ''.

    Returns:
        list[str]: ``'name (k of n values)'`` per bad tensor.
    """
    bad = []
    if isinstance(tree, torch.Tensor):
        if tree.is_floating_point() or tree.is_complex():
            count = int((~torch.isfinite(tree.detach())).sum())
            if count:
                bad.append(f'{prefix} ({count} of {tree.numel()} values)')
    elif isinstance(tree, dict):
        for key, value in tree.items():
            bad += non_finite_tensors(value, f'{prefix}.{key}'.lstrip('.'))
    elif isinstance(tree, (list, tuple)):
        for i, value in enumerate(tree):
            bad += non_finite_tensors(value, f'{prefix}.{i}'.lstrip('.'))
    return bad


def last_good_checkpoint(runner) -> str:
    """A sentence naming the checkpoint ``--resume`` would start from."""
    pointer = osp.join(runner.work_dir, 'last_checkpoint')
    target = ''
    if osp.isfile(pointer):
        with open(pointer) as f:
            target = f.read().strip()
    if target and osp.isfile(target):
        return (f'the last good checkpoint, {target}, is kept: resume from '
                'it with --resume')
    return 'no checkpoint was written before'


@HOOKS.register_module()
class NonFiniteLossHook(Hook):
    """Raise :class:`NonFiniteLossError` when training diverges.

    Listed in ``custom_hooks`` of ``configs/_base_/default_runtime.py``.
    In distributed training every rank learns whether any rank saw a bad
    loss (one all-reduce of a flag), so all ranks stop together instead of
    the healthy ones waiting forever at the next collective.

    Args:
        interval (int): Check the losses every ``interval`` iterations. A
            larger value saves the flag's all-reduce; the weights are still
            checked before every save. Defaults to 1.
    """

    priority = 'BELOW_NORMAL'

    def __init__(self, interval: int = 1) -> None:
        if interval < 1:
            raise ValueError(f'NonFiniteLossHook: expected interval >= 1, '
                             f'got {interval}.')
        self.interval = interval

    def after_train_iter(self,
                         runner,
                         batch_idx: int,
                         data_batch=None,
                         outputs: Optional[dict] = None) -> None:
        """Check this iteration's loss terms and gradient norm.

        Args:
            runner (Runner): The runner.
            batch_idx (int): Index of the batch in the epoch.
            data_batch (dict, optional): Unused.
            outputs (dict, optional): ``log_vars`` of ``train_step``.

        Raises:
            NonFiniteLossError: If a term on any rank is NaN or inf.
        """
        if not self.every_n_train_iters(runner, self.interval):
            return
        bad = non_finite_terms(outputs)
        grad_norm = self._grad_norm(runner)
        if grad_norm is not None:
            bad['grad_norm'] = grad_norm
        any_rank_bad = bool(bad)
        if get_world_size() > 1:
            flag = torch.tensor([float(any_rank_bad)])
            all_reduce(flag, op='max')
            any_rank_bad = bool(flag.item())
        if not any_rank_bad:
            return
        terms = (', '.join(f'{k}={v}' for k, v in bad.items())
                 if bad else 'finite here, non-finite on another rank')
        where = f'iteration {runner.iter + 1}'
        if hasattr(runner.train_loop, 'max_epochs'):
            where += f' (epoch {runner.epoch + 1}, batch {batch_idx + 1})'
        raise NonFiniteLossError(
            f'Non-finite loss at {where}: {terms}. Training stopped before '
            f'saving a checkpoint; {last_good_checkpoint(runner)}. Lower '
            'the learning rate or check the inputs of this iteration.')

    @staticmethod
    def _grad_norm(runner) -> Optional[float]:
        """This iteration's logged gradient norm if it is not finite."""
        wrapper = getattr(runner, 'optim_wrapper', None)
        if wrapper is None or type(wrapper).__name__ == 'AmpOptimWrapper':
            return None
        scalars = runner.message_hub.log_scalars
        buffer = scalars.get('train/grad_norm')
        # Logged at every optimiser step; a bad value never outlives the
        # iteration that logged it, because this hook raises there.
        if buffer is None or not len(buffer.data[0]):
            return None
        value = float(buffer.current())
        if torch.isfinite(torch.tensor(value)):
            return None
        return value

    def before_save_checkpoint(self, runner, checkpoint: dict) -> None:
        """Refuse to write non-finite weights or optimiser state.

        Args:
            runner (Runner): The runner.
            checkpoint (dict): What is about to be saved.

        Raises:
            NonFiniteLossError: Naming the first bad tensors.
        """
        bad = non_finite_tensors(checkpoint.get('state_dict', {}),
                                 'state_dict')
        bad += non_finite_tensors(checkpoint.get('optimizer', {}),
                                  'optimizer')
        if not bad:
            return
        shown = ', '.join(bad[:5]) + (f' and {len(bad) - 5} more'
                                      if len(bad) > 5 else '')
        meta = checkpoint.get('meta', {})
        raise NonFiniteLossError(
            f'Non-finite weights after iteration {meta.get("iter")} (epoch '
            f'{meta.get("epoch")}), found before saving a checkpoint: '
            f'{shown}. '
            'A step exploded them while its loss was still finite. Nothing '
            f'was saved or deleted; {last_good_checkpoint(runner)}. Lower '
            'the learning rate or clip gradients (optim_wrapper.clip_grad).')
