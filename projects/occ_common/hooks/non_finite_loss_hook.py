"""Stop training at the first NaN / inf loss, before it reaches a checkpoint.

By the time a hook sees the losses of an iteration the optimiser has
already stepped with them, so the weights in memory may be NaN. Within
``after_train_iter`` hooks run by priority; ``CheckpointHook`` (priority
``VERY_LOW``) saves there in iteration-based runs and in
``after_train_epoch`` in epoch-based ones, which come later still. This
hook runs at ``BELOW_NORMAL``, after ``LoggerHook`` (which logs the bad
iteration if it falls on its interval) and before ``CheckpointHook``, and
raises: no checkpoint is written or rotated away after the loss went bad.
"""
from typing import Dict, Optional

import torch
from mmdet3d.registry import HOOKS
from mmengine.dist import all_reduce, get_world_size
from mmengine.hooks import Hook


class NonFiniteLossError(FloatingPointError):
    """A loss term was NaN or infinite; raised by :class:`NonFiniteLossHook`.
    """


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


@HOOKS.register_module()
class NonFiniteLossHook(Hook):
    """Raise :class:`NonFiniteLossError` naming the iteration and the terms.

    Listed in ``custom_hooks`` of ``configs/_base_/default_runtime.py``.
    In distributed training every rank learns whether any rank saw a bad
    loss (one all-reduce of a flag), so all ranks stop together instead of
    the healthy ones waiting forever at the next collective.

    Args:
        interval (int): Check every ``interval`` iterations. A larger value
            saves the flag's all-reduce but may let a checkpoint of NaN
            weights through. Defaults to 1.
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
        """Check this iteration's loss terms.

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
        any_rank_bad = bool(bad)
        if get_world_size() > 1:
            flag = torch.tensor([float(any_rank_bad)])
            all_reduce(flag, op='max')
            any_rank_bad = bool(flag.item())
        if not any_rank_bad:
            return
        terms = (', '.join(f'{k}={v}' for k, v in bad.items())
                 if bad else 'finite here, non-finite on another rank')
        last = runner.message_hub.get_info('last_ckpt')
        kept = (f'the last checkpoint written is {last}'
                if last else 'no checkpoint was written in this run')
        where = f'iteration {runner.iter + 1}'
        if hasattr(runner.train_loop, 'max_epochs'):
            where += f' (epoch {runner.epoch + 1}, batch {batch_idx + 1})'
        raise NonFiniteLossError(
            f'Non-finite loss at {where}: {terms}. '
            f'Training stopped before saving a checkpoint; {kept}. Lower '
            'the learning rate or check the inputs of this iteration, then '
            'resume with --resume.')
