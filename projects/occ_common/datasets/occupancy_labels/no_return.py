"""Rays that returned nothing, recovered from a spinning LiDAR's pattern.

A ``.pcd.bin`` lists returns only, yet a beam fired at the sky crossed
free space too. A spinning LiDAR fires every beam (ring) at evenly spaced
azimuths, and nuScenes stores each return's ring index, so the fired rays
without a return can be told from those present:

* in each sweep the azimuth step is the median gap between neighbouring
  returns of a ring (most neighbours are one step apart), and the azimuth
  phase the circular mean of the returns' azimuths modulo that step
  (:func:`firing_pattern`);
* each ring's elevation is the median elevation of its returns over the
  scene; rings between observed ones are interpolated, as a spinning
  LiDAR's rings are indexed by elevation (:func:`ring_elevations`);
* every (ring, azimuth step) of a sweep without a return is a ray that
  travelled the sensor's range without hitting anything
  (:func:`missing_directions`).

These rays add to ``mask_lidar`` only; they never carve free space (a
dropped return is no proof of it).
"""
from dataclasses import dataclass
from typing import List, Optional

import numpy as np

#: Column of the ring index in nuScenes' x, y, z, intensity, ring.
RING_COLUMN = 4


@dataclass
class FiringPattern:
    """Which rays of one sweep returned.

    Args:
        fired (np.ndarray): bool, ``[ring, azimuth step]`` has a return.
            Shape (R, A).
        phase (float): Azimuth of step 0, radians.
        ring_elevation (np.ndarray): Median elevation of each ring's
            returns, NaN for a ring without any. Shape (R,).
    """
    fired: np.ndarray
    phase: float
    ring_elevation: np.ndarray


def firing_pattern(points: np.ndarray) -> Optional[FiringPattern]:
    """The firing pattern of one sweep from its returns.

    Args:
        points (np.ndarray): Returns ``x, y, z, intensity, ring``, sensor
            frame. Shape (N, 5).

    Returns:
        FiringPattern, optional: None when no ring has two returns (the
        azimuth step cannot be told).
    """
    ring = points[:, RING_COLUMN].astype(np.int64)
    azimuth = np.mod(np.arctan2(points[:, 1], points[:, 0]), 2 * np.pi)
    elevation = np.arctan2(points[:, 2], np.hypot(points[:, 0],
                                                  points[:, 1]))
    order = np.lexsort((azimuth, ring))
    ring, azimuth, elevation = ring[order], azimuth[order], elevation[order]
    gaps = np.diff(azimuth)[ring[1:] == ring[:-1]]
    gaps = gaps[gaps > 1e-6]
    if not len(gaps):
        return None
    bins = int(round(2 * np.pi / float(np.median(gaps))))
    step = 2 * np.pi / bins
    turn = np.exp(1j * azimuth * bins)
    phase = float(np.mod(np.angle(turn.mean()), 2 * np.pi)) / bins
    column = np.mod(np.round((azimuth - phase) / step).astype(np.int64),
                    bins)
    num_rings = int(ring.max()) + 1
    fired = np.zeros((num_rings, bins), dtype=bool)
    fired[ring, column] = True
    rings, starts = np.unique(ring, return_index=True)
    medians = np.full(num_rings, np.nan)
    medians[rings] = [np.median(part)
                      for part in np.split(elevation, starts[1:])]
    return FiringPattern(fired=fired, phase=phase, ring_elevation=medians)


def ring_elevations(patterns: List[FiringPattern]) -> np.ndarray:
    """Each ring's elevation over a scene's sweeps (interpolated where a
    ring never returned between rings that did).

    Args:
        patterns (List[FiringPattern]): The sweeps' patterns.

    Returns:
        np.ndarray: Radians, NaN where unknown. Shape (max rings,).
    """
    if not patterns:
        return np.zeros(0)
    num = max(len(p.ring_elevation) for p in patterns)
    table = np.full((len(patterns), num), np.nan)
    for row, pattern in zip(table, patterns):
        row[:len(pattern.ring_elevation)] = pattern.ring_elevation
    unknown = np.all(np.isnan(table), axis=0)
    elevation = np.full(num, np.nan)
    elevation[~unknown] = np.nanmedian(table[:, ~unknown], axis=0)
    seen = np.flatnonzero(~unknown)
    if len(seen) >= 2:
        inner = np.arange(seen[0], seen[-1] + 1)
        elevation[inner] = np.interp(inner, seen, elevation[seen])
    return elevation


def missing_directions(pattern: FiringPattern,
                       elevations: np.ndarray) -> np.ndarray:
    """Unit directions (sensor frame) of the rays of a sweep that returned
    nothing, for the rings of known elevation.

    Args:
        pattern (FiringPattern): The sweep's pattern.
        elevations (np.ndarray): :func:`ring_elevations`. Shape (R,).

    Returns:
        np.ndarray: Shape (M, 3).
    """
    bins = pattern.fired.shape[1]
    fired = np.zeros((len(elevations), bins), dtype=bool)
    rows = min(len(elevations), len(pattern.fired))
    fired[:rows] = pattern.fired[:rows]
    ring, column = np.nonzero(~fired & np.isfinite(elevations)[:, None])
    elevation = elevations[ring]
    heading = pattern.phase + column * (2 * np.pi / bins)
    return np.stack([np.cos(elevation) * np.cos(heading),
                     np.cos(elevation) * np.sin(heading),
                     np.sin(elevation)], axis=1)
