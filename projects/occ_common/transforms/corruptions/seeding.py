"""Random draws of a corruption, fixed by what is corrupted.

Every random choice of :class:`~.occ_corruption.OccCorruption` (noise, the
views that crash, the points that drop) comes from one generator seeded by
the sample's token, the condition and the run's seed, so the same input
always comes out the same: in any worker process, in any order, on any
machine. Python's ``hash`` is salted per process, so the seed is a SHA-256
digest instead.

The severity is left out on purpose: the levels of a condition share
their draws (common random numbers), so two severities of a sample differ
by the severity's parameters alone. The views that crash at severity 2
crash at 3 too, the points fog keeps at severity 5 it keeps at 1, the
noise is one pattern scaled: where a level only scales the corruption,
its effect grows with severity on every sample, not only on average.
"""
import hashlib

import numpy as np


def corruption_rng(sample: str, condition: str,
                   seed: int) -> np.random.Generator:
    """The generator of one sample under one condition.

    Args:
        sample (str): The sample's token (its ``sample_idx`` where a
            pipeline has no token).
        condition (str): The condition's name.
        seed (int): The run's seed.

    Returns:
        np.random.Generator: PCG64, seeded from the three values.
    """
    key = f'{sample}\x00{condition}\x00{int(seed)}'
    digest = hashlib.sha256(key.encode('utf-8')).digest()
    return np.random.default_rng(int.from_bytes(digest[:16], 'little'))
