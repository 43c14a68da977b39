"""Random augmentation seeded per (seed, epoch, sample index).

The transforms draw from the global ``np.random`` (and may use ``random``
or ``torch``), whose state a checkpoint does not hold: a resumed run drew
other augmentations than an uninterrupted one (229 of 317 tensors of the
tiny SDG-Fusion differed after a kill and ``--resume``). Instead of saving
generator states, every sample's pipeline runs with the three generators
seeded from ``(seed, epoch, index)`` and restored afterwards, so

- a resumed run repeats the uninterrupted one bit for bit (the Runner
  restores ``seed`` and ``epoch``);
- the result does not depend on the number of dataloader workers or
  ranks, or on which worker loads a sample;
- every epoch still draws new augmentations.

``epoch`` reaches the dataloader workers through a tensor in shared memory
(:class:`EpochSeed`), which :class:`~projects.occ_common.engine.hooks.
AugmentationSeedHook` sets before each training epoch, before the epoch's
first index is sent to a worker (persistent workers included).

A dataset wrapper that repeats indices within an epoch (``RepeatDataset``,
CBGS) gives every repeat of a sample the same augmentation in that epoch.
"""
import contextlib
import random
from typing import Iterator, Optional, Tuple

import numpy as np
import torch


@contextlib.contextmanager
def sample_random_state(seed: int, epoch: int, index: int) -> Iterator[None]:
    """Seed ``np.random``, ``random`` and torch's CPU generator for one
    sample, and restore all three afterwards.

    Args:
        seed (int): The run's seed (``runner.seed``), >= 0.
        epoch (int): The 0-based training epoch.
        index (int): The sample's index in the dataset.

    Yields:
        None
    """
    words = np.random.SeedSequence([int(seed), int(epoch),
                                    int(index)]).generate_state(4)
    np_state = np.random.get_state()
    py_state = random.getstate()
    with torch.random.fork_rng(devices=[]):
        np.random.seed(words[:2])
        random.seed(int(words[2]))
        torch.manual_seed(int(words[3]))
        try:
            yield
        finally:
            np.random.set_state(np_state)
            random.setstate(py_state)


class EpochSeed:
    """``(seed, epoch)`` shared with the dataloader workers.

    The pair lives in a shared-memory tensor, so the main process can
    update it after the workers were started. Unset, a dataset uses the
    global generators as they are (evaluation, or a dataset used outside a
    Runner).
    """

    def __init__(self) -> None:
        self._state = torch.full((2, ), -1, dtype=torch.int64)
        self._state.share_memory_()

    def set(self, seed: int, epoch: int) -> None:
        """Set the run's seed and the 0-based epoch (both >= 0)."""
        if seed is None or seed < 0 or epoch < 0:
            raise ValueError('EpochSeed: expected seed >= 0 and epoch >= 0,'
                             f' got seed={seed}, epoch={epoch}')
        self._state[0] = int(seed)
        self._state[1] = int(epoch)

    def get(self) -> Optional[Tuple[int, int]]:
        """``(seed, epoch)``, or None if never set."""
        seed, epoch = self._state.tolist()
        return None if seed < 0 else (seed, epoch)

    def context(self, index: int):
        """The random state of sample ``index`` this epoch (a context)."""
        state = self.get()
        if state is None:
            return contextlib.nullcontext()
        return sample_random_state(state[0], state[1], index)
