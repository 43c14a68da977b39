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

from mmdet3d.registry import HOOKS
from mmengine.hooks import Hook
from mmengine.model import is_model_wrapper

from ...fileio.checkpoint_schemes import install_checkpoint_loader
from ..checkpoint_check import (EVALUATE, FINE_TUNE, RESUME,
                                check_checkpoint_state)
from ..resume_checks import kept_schedule_ends, resumed_state_changes


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
        """Refuse NaN / inf weights and, unless allowed, other keys; on a
        resume also optimizer and schedule values that differ from the
        config's (:mod:`..resume_checks`).

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
        if resuming:
            for line in kept_schedule_ends(runner, checkpoint):
                runner.logger.warning(f'--resume: {line}.')
            changes = resumed_state_changes(runner, checkpoint)
            if changes:
                raise ValueError(
                    f'{source} holds optimizer / schedule values other than '
                    f'the config\'s, and resuming would restore them over '
                    f'it, ignoring the config: {"; ".join(changes)}. Resume '
                    'with the values of the interrupted run, or start a new '
                    'run from its weights with --cfg-options load_from=PATH '
                    'to train with the new ones.')
