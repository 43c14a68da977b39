"""Refuse to evaluate, fine-tune from or resume a checkpoint that is not
this model's.

mmengine loads a checkpoint non-strictly and only logs the mismatched keys
(among ~1,100 log lines): a checkpoint of the other model evaluated with
exit code 0 and the metric of a randomly initialised model, an all-NaN
checkpoint evaluated too, ``load_from=`` the other model's checkpoint
trained from random weights with two warning lines, and ``--resume`` with
it loaded its weights and then failed in the optimizer without naming the
file. ``tools/test.py`` and ``tools/train.py`` add this hook, which checks
the checkpoint when the Runner has loaded it and before it is copied into
the model, on every rank alike (mmengine's own strict mode raises on rank 0
only and leaves the other ranks waiting).
"""
import os.path as osp
import re
from typing import Dict, List

from mmdet3d.registry import HOOKS
from mmengine.hooks import Hook
from mmengine.model import is_model_wrapper

from ...fileio.checkpoint_schemes import install_checkpoint_loader
from .non_finite_loss_hook import non_finite_tensors

#: The consequences :func:`check_checkpoint_state` names.
EVALUATE = 'Evaluating it would report a partly random model.'
FINE_TUNE = ('Training from it would start the missing or reshaped parts '
             'from random weights.')
RESUME = ('A run resumes only from a checkpoint of its own model (the '
          'optimizer state would not fit either).')


def _examples(items: List[str], count: int = 3) -> str:
    shown = ', '.join(items[:count])
    return shown + (f', ... ({len(items)} in all)'
                    if len(items) > count else '')


def state_dict_mismatch(model_state: Dict,
                        checkpoint_state: Dict) -> List[str]:
    """How a checkpoint's state dict differs from a model's.

    Args:
        model_state (dict): ``model.state_dict()``.
        checkpoint_state (dict): The checkpoint's ``state_dict``, with any
            ``module.`` prefix removed.

    Returns:
        list[str]: One sentence per kind of difference (missing keys,
        unexpected keys, other shapes); empty if they match. BatchNorm's
        ``num_batches_tracked`` may be missing, as mmengine allows.
    """
    missing = [
        k for k in model_state
        if k not in checkpoint_state and not k.endswith('num_batches_tracked')
    ]
    unexpected = [k for k in checkpoint_state if k not in model_state]
    shapes = [
        f'{k} {tuple(checkpoint_state[k].shape)} vs '
        f'{tuple(model_state[k].shape)}' for k in model_state
        if k in checkpoint_state and hasattr(checkpoint_state[k], 'shape')
        and tuple(checkpoint_state[k].shape) != tuple(model_state[k].shape)
    ]
    found = []
    if missing:
        found.append(f'{len(missing)} of the model\'s {len(model_state)} '
                     f'tensors are missing ({_examples(missing)})')
    if unexpected:
        found.append(f'{len(unexpected)} keys are not the model\'s '
                     f'({_examples(unexpected)})')
    if shapes:
        found.append(f'{len(shapes)} tensors have another shape '
                     f'(checkpoint vs model: {_examples(shapes)})')
    return found


def check_checkpoint_state(model,
                           state: Dict,
                           source: str,
                           config: str,
                           allow_key_mismatch: bool = False,
                           hint: str = '',
                           consequence: str = EVALUATE) -> Dict:
    """Refuse a state dict with NaN / inf weights or, unless allowed, one
    that is not ``model``'s.

    Shared by :class:`CheckpointMatchHook` (``tools/test.py``) and
    :func:`load_checked_weights` (the tools that load weights themselves).

    Args:
        model (nn.Module): The model the weights are for (not a wrapper).
        state (dict): The checkpoint's ``state_dict``.
        source (str): The checkpoint's name, for the messages.
        config (str): The config's file name, for the messages.
        allow_key_mismatch (bool): Only refuse non-finite weights.
            Defaults to False.
        hint (str): Appended to the key-mismatch message (what the caller
            can do about it). Defaults to ''.
        consequence (str): What using the checkpoint would do, in the
            key-mismatch message. Defaults to :data:`EVALUATE`.

    Returns:
        dict: ``state`` with any ``module.`` prefix removed.

    Raises:
        ValueError: Naming the checkpoint and what is wrong.
    """
    bad = non_finite_tensors(state)
    if bad:
        raise ValueError(
            f'{source} holds non-finite weights: {_examples(bad)}. It '
            'is the checkpoint of a diverged run; evaluate the last good'
            ' one instead.')
    state = {re.sub(r'^module\.', '', k): v for k, v in state.items()}
    if allow_key_mismatch:
        return state
    found = state_dict_mismatch(model.state_dict(), state)
    if found:
        raise ValueError(
            f'{source} does not fit the model of {config}: '
            f'{"; ".join(found)}. {consequence}{hint}')
    return state


def load_checked_weights(model,
                         loaded,
                         source: str,
                         config: str,
                         allow_key_mismatch: bool = False,
                         hint: str = '',
                         consequence: str = EVALUATE) -> None:
    """Copy a loaded checkpoint's weights into ``model`` once
    :func:`check_checkpoint_state` accepts them.

    For the tools that load a checkpoint themselves (``demo/occ_demo.py``,
    ``tools/deployment/export_onnx.py``, the analysis tools), as mmdet3d's
    ``init_model`` does but with ``tools/test.py``'s checks.

    Args:
        model (nn.Module): The model the weights are for.
        loaded (object): What the checkpoint file held: a Runner
            checkpoint (``dict(state_dict=...)``) or a bare state dict.
        source, config, allow_key_mismatch, hint, consequence: As for
            :func:`check_checkpoint_state`.

    Raises:
        ValueError: If ``loaded`` holds no state dict, or
            :func:`check_checkpoint_state` refuses it.
    """
    state = loaded.get('state_dict', loaded) if isinstance(loaded,
                                                           dict) else None
    if not isinstance(state, dict):
        raise ValueError(f'{source}: expected a checkpoint dict (a state '
                         'dict or dict(state_dict=...)), got '
                         f'{type(loaded).__name__}')
    state = check_checkpoint_state(model, state, source, config,
                                   allow_key_mismatch, hint, consequence)
    model.load_state_dict(state, strict=False)  # num_batches_tracked


def loaded_file(runner) -> str:
    """The checkpoint the Runner loads, for messages.

    Args:
        runner (Runner): The runner.

    Returns:
        str: ``load_from``, or the ``last_checkpoint`` pointer's target of
        an auto-resume, or ``'the checkpoint'``.
    """
    load_from = runner.cfg.get('load_from')
    if load_from:
        return load_from
    pointer = osp.join(runner.work_dir, 'last_checkpoint')
    if osp.isfile(pointer):
        with open(pointer) as f:
            return f.read().strip() or 'the checkpoint'
    return 'the checkpoint'


@HOOKS.register_module()
class CheckpointMatchHook(Hook):
    """Check the loaded checkpoint against the model before it is used.

    ``before_run`` installs the restricted checkpoint loader (so that
    ``tools/test.py`` loads restrictedly even with a config that lacks
    ``WeightsOnlyCheckpointHook``). ``tools/test.py`` adds it for the
    evaluated checkpoint, ``tools/train.py`` for ``load_from`` and
    ``--resume``.

    Args:
        allow_key_mismatch (bool): Only refuse non-finite weights, accept
            missing, unexpected and reshaped keys (mmengine's behaviour).
            Never for a resume, which needs the model's own checkpoint.
            Defaults to False.
        training (bool): Whether the Runner trains (the messages then speak
            of fine-tuning / resuming and of tools/train.py's flag).
            Defaults to False (evaluation).
    """

    priority = 'VERY_HIGH'

    def __init__(self,
                 allow_key_mismatch: bool = False,
                 training: bool = False) -> None:
        self.allow_key_mismatch = allow_key_mismatch
        self.training = training

    def before_run(self, runner) -> None:
        """Install the restricted loader before anything is loaded."""
        install_checkpoint_loader()

    def after_load_checkpoint(self, runner, checkpoint: dict) -> None:
        """Refuse NaN / inf weights and, unless allowed, other keys.

        Raises:
            ValueError: Naming the checkpoint and what is wrong.
        """
        model = runner.model.module if is_model_wrapper(
            runner.model) else runner.model
        source = loaded_file(runner)
        resuming = self.training and runner.cfg.get('resume', False)
        if resuming:
            consequence, hint = RESUME, (
                ' Check --resume, or train from it with load_from= '
                '(--cfg-options load_from=PATH) and --allow-key-mismatch.')
            source = f'--resume: {source}'
        elif self.training:
            consequence, hint = FINE_TUNE, (
                ' Check load_from, or pass --allow-key-mismatch to '
                'tools/train.py to fine-tune from it anyway.')
        else:
            consequence, hint = EVALUATE, (
                ' Check the config and the checkpoint, or pass '
                '--allow-key-mismatch to evaluate anyway.')
        check_checkpoint_state(
            model, checkpoint.get('state_dict', checkpoint), source,
            runner.cfg.filename, self.allow_key_mismatch and not resuming,
            hint, consequence)
