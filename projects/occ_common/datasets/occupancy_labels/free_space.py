"""Free-space carving of the static points.

Spurious returns (rain drops, dust) and whatever moved without a box sit
in space that other rays of the sequence crossed. Every ray of the scene
is walked through one world-aligned grid (:func:`scene_grid`), counting
per voxel the rays that passed through it without ending there; a static
point survives where returns make up at least ``min_hit_ratio`` of
returns plus passes (:func:`carve`), a share surfaces keep even when rays
graze them and open air does not.
"""
from typing import Iterable, List

import numpy as np

from ...geometry.voxel_walk import OccGrid, pass_counts
from .accumulation import SweepRays


def scene_grid(extents: Iterable[np.ndarray], voxel: float) -> OccGrid:
    """A global, axis-aligned grid covering given boxes.

    Args:
        extents (Iterable[np.ndarray]): Corners of the regions to cover
            (the key frames' label grids), global. Shape (K, 3) each.
        voxel (float): Voxel edge, metres.

    Returns:
        OccGrid: The grid, its lower corner on a multiple of ``voxel``.
    """
    corners = np.concatenate([np.asarray(c).reshape(-1, 3) for c in extents])
    lower = np.floor(corners.min(axis=0) / voxel) * voxel
    shape = np.ceil((corners.max(axis=0) - lower) / voxel).astype(int)
    return OccGrid(tuple(float(v) for v in lower), float(voxel),
                   tuple(int(v) for v in np.maximum(shape, 1)))


def ray_passes(grid: OccGrid, rays: List[SweepRays]) -> np.ndarray:
    """Rays that crossed every voxel of ``grid`` (see
    :func:`..geometry.voxel_walk.pass_counts`), summed over sweeps.

    Args:
        grid (OccGrid): Global grid.
        rays (List[SweepRays]): The sweeps' returns.

    Returns:
        np.ndarray: int64 counts. Shape (X, Y, Z).
    """
    passes = np.zeros(grid.shape, dtype=np.int64)
    for sweep in rays:
        if not len(sweep.ends):
            continue
        delta = sweep.ends - sweep.origin
        length = np.linalg.norm(delta, axis=1)
        ok = length > 1e-6
        passes += pass_counts(grid, sweep.origin, delta[ok] / length[ok,
                                                                     None],
                              length[ok])
    return passes


def carve(grid: OccGrid, points: np.ndarray, passes: np.ndarray,
          min_hit_ratio: float) -> np.ndarray:
    """Which static points survive carving.

    Args:
        grid (OccGrid): The grid of ``passes`` (global).
        points (np.ndarray): Static points, global. Shape (S, 3).
        passes (np.ndarray): :func:`ray_passes`. Shape (X, Y, Z).
        min_hit_ratio (float): See the module docstring.

    Returns:
        np.ndarray: bool, kept points (those outside the grid are kept).
        Shape (S,).
    """
    ijk, inside = grid.voxel_index(points)
    flat = grid.flat_index(ijk)
    hits = np.bincount(flat, minlength=passes.size)[flat]
    ratio = hits / (hits + passes.ravel()[flat])
    keep = np.ones(len(points), dtype=bool)
    keep[inside] = ratio >= min_hit_ratio
    return keep
