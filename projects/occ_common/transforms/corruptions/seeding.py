"""Random draws of a corruption, fixed by what is corrupted.

Every random choice of :class:`~.occ_corruption.OccCorruption` (noise, the
views that crash, the points that drop) comes from one generator seeded by
the sample's token, the condition, the severity and the run's seed, so the
same input always comes out the same: in any worker process, in any order,
on any machine. Python's ``hash`` is salted per process, so the seed is a
SHA-256 digest instead.
"""
import hashlib

import numpy as np


def corruption_rng(sample: str, condition: str, severity: int,
                   seed: int) -> np.random.Generator:
    """The generator of one corrupted sample.

    Args:
        sample (str): The sample's token (its ``sample_idx`` where a
            pipeline has no token).
        condition (str): The condition's name.
        severity (int): Its severity, 1-based.
        seed (int): The run's seed.

    Returns:
        np.random.Generator: PCG64, seeded from the four values.
    """
    key = f'{sample}\x00{condition}\x00{int(severity)}\x00{int(seed)}'
    digest = hashlib.sha256(key.encode('utf-8')).digest()
    return np.random.default_rng(int.from_bytes(digest[:16], 'little'))
