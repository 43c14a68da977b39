"""Save the global random state with every checkpoint and restore it on
``--resume``, so that a resumed run draws what an uninterrupted one draws.

DropPath, dropout and anything else drawing from torch's global generator
(and numpy's and Python's) use a state that a Runner checkpoint does not
hold: an OccCylindrical run resumed from epoch 1 drew other DropPath masks
from its first iteration (loss 38.5434 against 38.5056; 366 of 417
tensors differed at epoch 3). This hook

- stores the state of every rank in ``checkpoint['rng_state']``
  (``{'world_size': W, 'ranks': [state of rank 0, ...]}``, each state a
  dict of torch's CPU ``ByteTensor``, CUDA's where CUDA is in use, numpy's
  and Python's state; all of them load through the restricted checkpoint
  loader). Only rank 0 saves, so with several ranks the states are
  gathered just before a checkpoint hook saves (the hook runs before
  ``CheckpointHook``, priority ``LOW``);
- on a resume, gives each rank its own state back where the uninterrupted
  run would have drawn next: before the epoch's data loader iterator
  (which draws its workers' base seed from the global generator) when
  the loader starts a new iterator each epoch, else before the first
  iteration (persistent workers, iteration-based loops);
- keeps validation from drawing on the training's stream (the state is
  put back after each validation), since a resumed run does not repeat
  the validation that followed its checkpoint.

A checkpoint without ``rng_state`` (saved before this hook) resumes with
one warning that random layers draw differently from then on.
"""
import random
from typing import Dict, List, Optional

import numpy as np
import torch
from mmdet3d.registry import HOOKS
from mmengine.dist import all_gather_object
from mmengine.hooks import CheckpointHook, Hook
from mmengine.runner import EpochBasedTrainLoop

from .checkpoint_match_hook import loaded_file

#: Where the states are in a checkpoint.
KEY = 'rng_state'


def get_random_state() -> Dict:
    """This process's global random state.

    Returns:
        dict: ``torch`` (CPU ``ByteTensor``), ``cuda`` (the current
        device's, only once CUDA is initialised), ``numpy`` and
        ``python``.
    """
    state = dict(
        torch=torch.get_rng_state(),
        numpy=np.random.get_state(),
        python=random.getstate())
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        state['cuda'] = torch.cuda.get_rng_state()
    return state


def set_random_state(state: Dict, source: str = 'the checkpoint') -> None:
    """Restore what :func:`get_random_state` returned.

    Args:
        state (dict): A state of :func:`get_random_state`, possibly loaded
            onto another device.
        source (str): The checkpoint's name, for the messages. Defaults to
            'the checkpoint'.

    Raises:
        ValueError: If ``state`` is not such a state.
    """
    try:
        torch_state = state['torch'].cpu()
        cuda_state = state.get('cuda')
        np.random.set_state(tuple(state['numpy']))
        random.setstate(_tuples(state['python']))
        torch.set_rng_state(torch_state)
        if cuda_state is not None and torch.cuda.is_available():
            torch.cuda.set_rng_state(cuda_state.cpu())
    except (AttributeError, KeyError, TypeError, ValueError,
            RuntimeError) as err:
        raise ValueError(
            f'{source}: its {KEY} is not a random state saved by '
            f'RandomStateHook ({type(err).__name__}: {err}).') from None


def _tuples(value):
    """``random.setstate`` wants tuples all the way down."""
    if isinstance(value, (list, tuple)):
        return tuple(_tuples(item) for item in value)
    return value


def _checkpoint_hook_saves(runner, after_epoch: bool) -> bool:
    """Whether a ``CheckpointHook`` saves at this ``after_train_epoch``
    (or ``after_train_iter``), by its own rules."""
    for hook in runner.hooks:
        if (not isinstance(hook, CheckpointHook)
                or hook.by_epoch != after_epoch):
            continue
        if after_epoch:
            due = hook.every_n_epochs(runner, hook.interval, hook.save_begin)
            last = hook.is_last_train_epoch(runner)
        else:
            due = hook.every_n_train_iters(runner, hook.interval,
                                           hook.save_begin)
            last = hook.is_last_train_iter(runner)
        if due or (hook.save_last and last):
            return True
    return False


@HOOKS.register_module()
class RandomStateHook(Hook):
    """Make ``--resume`` continue the global random streams (see the
    module doc).

    Listed in ``custom_hooks`` of ``configs/_base_/default_runtime.py``.
    """

    priority = 'LOW'  # before CheckpointHook (VERY_LOW) gathers

    def __init__(self) -> None:
        self._gathered: Optional[tuple] = None  # (iter, states of ranks)
        self._pending: Optional[Dict] = None  # state to restore
        self._source = ''
        self._validation_state: Optional[Dict] = None

    # Saving.
    def _gather(self, runner, after_epoch: bool) -> None:
        if runner.world_size > 1 and _checkpoint_hook_saves(
                runner, after_epoch):
            self._gathered = (runner.iter,
                              all_gather_object(get_random_state()))

    def after_train_iter(self, runner, batch_idx: int, data_batch=None,
                         outputs=None) -> None:
        """Gather the ranks' states if a checkpoint is saved now."""
        self._gather(runner, after_epoch=False)

    def after_train_epoch(self, runner) -> None:
        """Gather the ranks' states if a checkpoint is saved now."""
        self._gather(runner, after_epoch=True)

    def before_save_checkpoint(self, runner, checkpoint: Dict) -> None:
        """Store every rank's state (rank 0's alone where none was
        gathered for this step, e.g. a best checkpoint)."""
        ranks: List[Dict] = [get_random_state()]
        if self._gathered is not None and self._gathered[0] == runner.iter:
            ranks = self._gathered[1]
        checkpoint[KEY] = dict(world_size=runner.world_size, ranks=ranks)

    # Restoring.
    def after_load_checkpoint(self, runner, checkpoint: Dict) -> None:
        """On a resume, keep this rank's saved state for
        :meth:`_restore`."""
        if not getattr(runner, '_resume', runner.cfg.get('resume', False)):
            return  # load_from: a new run, with its own seed
        self._source = loaded_file(runner)
        saved = checkpoint.get(KEY)
        if saved is None:
            runner.logger.warning(
                f'RandomStateHook: {self._source} holds no random state '
                f'(saved without {type(self).__name__}): dropout, '
                'DropPath and other random layers draw differently from '
                'an uninterrupted run from here on.')
            return
        ranks = saved.get('ranks') if isinstance(saved, dict) else None
        if not isinstance(ranks, list) or not ranks:
            raise ValueError(f'{self._source}: its {KEY} holds no states '
                             f'of ranks ({type(saved).__name__}).')
        if runner.rank >= len(ranks) or runner.world_size != len(ranks):
            runner.logger.warning(
                f'RandomStateHook: {self._source} holds the random state '
                f'of {len(ranks)} rank(s), this run has '
                f'{runner.world_size}: ranks without a saved state keep '
                'their seed, and random layers draw differently from an '
                'uninterrupted run.')
        if runner.rank < len(ranks):
            self._pending = ranks[runner.rank]

    def _restore(self) -> None:
        state, self._pending = self._pending, None
        set_random_state(state, self._source)

    @staticmethod
    def _new_iterator_each_epoch(runner) -> bool:
        loader = runner.train_dataloader
        persistent = (getattr(loader, 'persistent_workers', False)
                      and getattr(loader, 'num_workers', 0) > 0)
        return (isinstance(runner.train_loop, EpochBasedTrainLoop)
                and not persistent)

    def before_train_epoch(self, runner) -> None:
        """Restore before the loader's new iterator draws its seed."""
        if self._pending is not None and self._new_iterator_each_epoch(
                runner):
            self._restore()

    def before_train_iter(self, runner, batch_idx: int,
                          data_batch=None) -> None:
        """Restore before the first iteration (other loaders and
        loops)."""
        if self._pending is not None:
            self._restore()

    # Validation draws nothing from the training's stream.
    def before_val(self, runner) -> None:
        """Set the training's random state aside."""
        self._validation_state = get_random_state()

    def after_val(self, runner) -> None:
        """Put the training's random state back."""
        if self._validation_state is not None:
            set_random_state(self._validation_state)
            self._validation_state = None
