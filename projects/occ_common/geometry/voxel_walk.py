"""Regular voxel grids and the exact voxel walk of rays through them.

The walk is Amanatides & Woo's ("A fast voxel traversal algorithm for ray
tracing", Eurographics 1987), vectorised over rays: every step advances
all unfinished rays by one voxel. It is shared by the synthetic world's
exact visibility masks and by the occupancy label generator
(``datasets/occupancy_labels``), so that the generator's masks differ from
the exact ones only through what it observed, never through the walk.

(RayIoU's walk in ``evaluation/ray_casting.py`` is a different contract:
it reproduces SparseOcc's CUDA kernel float for float and reports first
hits, not visited voxels.)
"""
from dataclasses import dataclass
from typing import Iterator, Optional, Tuple

import numpy as np


@dataclass(frozen=True)
class OccGrid:
    """A regular voxel grid.

    Args:
        lower (Tuple[float, float, float]): Minimum x, y, z corner, m.
        voxel_size (float): Edge of a voxel, m.
        shape (Tuple[int, int, int]): Voxels along x, y, z.
    """
    lower: Tuple[float, float, float]
    voxel_size: float
    shape: Tuple[int, int, int]

    @property
    def upper(self) -> np.ndarray:
        """Maximum x, y, z corner. Shape (3,)."""
        return np.asarray(self.lower) + np.asarray(self.shape) * (
            self.voxel_size)

    def centers(self, axis: int) -> np.ndarray:
        """Voxel centre coordinates along one axis. Shape (shape[axis],)."""
        return self.lower[axis] + (np.arange(self.shape[axis]) + 0.5) * (
            self.voxel_size)

    def voxel_index(self, points: np.ndarray) -> Tuple[np.ndarray,
                                                       np.ndarray]:
        """The voxel of every point.

        Args:
            points (np.ndarray): Coordinates in the grid's frame.
                Shape (N, 3).

        Returns:
            tuple[np.ndarray, np.ndarray]: ``ijk`` int64 indices of the
            points inside the grid, Shape (M, 3), and which points those
            are, bool, Shape (N,).
        """
        ijk = np.floor((np.asarray(points, np.float64).reshape(-1, 3)
                        - self.lower) / self.voxel_size).astype(np.int64)
        inside = ((ijk >= 0) & (ijk < np.asarray(self.shape))).all(axis=1)
        return ijk[inside], inside

    def flat_index(self, ijk: np.ndarray) -> np.ndarray:
        """Row-major flat index of voxel indices. Shape (M,)."""
        return np.ravel_multi_index(tuple(np.asarray(ijk).T), self.shape)


def walk_steps(grid: OccGrid, origins: np.ndarray, dirs: np.ndarray,
               lengths: np.ndarray, occupied: Optional[np.ndarray] = None
               ) -> Iterator[Tuple[np.ndarray, np.ndarray]]:
    """The voxels rays walk through, one step of all rays at a time.

    Every ray starts at its origin (or where it enters the grid) and ends
    after ``length`` metres, or at the first voxel of ``occupied`` it
    enters (that voxel is included), or where it leaves the grid.

    Args:
        grid (OccGrid): The grid; origins and directions are in its frame.
        origins (np.ndarray): Ray origins. Shape (R, 3) or (3,).
        dirs (np.ndarray): Unit ray directions. Shape (R, 3).
        lengths (np.ndarray): Ray lengths, metres. Shape (R,).
        occupied (np.ndarray, optional): Voxels that stop a ray. Shape
            (X, Y, Z). Defaults to None (rays run their full length).

    Yields:
        tuple[np.ndarray, np.ndarray]: The flat index of the voxel every
        unfinished ray is in, and whether the ray's length ends in it (its
        end point lies there). Shape (R_step,) each.
    """
    shape = np.asarray(grid.shape)
    lower = np.asarray(grid.lower, dtype=np.float64)
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    origins = np.broadcast_to(np.asarray(origins, np.float64), dirs.shape)
    lengths = np.broadcast_to(np.asarray(lengths, np.float64), len(dirs))
    tiny = np.where(dirs >= 0, 1e-12, -1e-12)
    inverse = 1.0 / np.where(np.abs(dirs) < 1e-12, tiny, dirs)
    t_a = (lower - origins) * inverse
    t_b = (grid.upper - origins) * inverse
    t_enter = np.maximum(np.minimum(t_a, t_b).max(axis=1), 0.0)
    t_end = np.minimum(np.maximum(t_a, t_b).min(axis=1), lengths)
    ends_inside = lengths <= t_end
    keep = t_enter <= t_end
    origins, dirs, inverse = origins[keep], dirs[keep], inverse[keep]
    t_enter, t_end, ends_inside = t_enter[keep], t_end[keep], ends_inside[
        keep]
    start = origins + t_enter[:, None] * dirs
    voxel = np.clip(np.floor((start - lower) / grid.voxel_size), 0,
                    shape - 1).astype(np.int64)
    sign = np.where(dirs >= 0, 1, -1)
    boundary = lower + (voxel + (sign > 0)) * grid.voxel_size
    t_next = (boundary - origins) * inverse
    t_delta = grid.voxel_size * np.abs(inverse)
    occupied_flat = None if occupied is None else occupied.ravel()
    strides = np.array([shape[1] * shape[2], shape[2], 1])
    while len(voxel):
        flat = voxel @ strides
        rows = np.arange(len(voxel))
        axis = np.argmin(t_next, axis=1)
        t_axis = t_next[rows, axis]
        stop = t_axis > t_end
        yield flat, stop & ends_inside
        if occupied_flat is not None:
            stop |= occupied_flat[flat]
        voxel[rows, axis] += sign[rows, axis]
        t_next[rows, axis] += t_delta[rows, axis]
        moved = voxel[rows, axis]
        stop |= (moved < 0) | (moved >= shape[axis])
        if stop.any():
            go = ~stop
            voxel, t_next, t_delta = voxel[go], t_next[go], t_delta[go]
            sign, t_end, ends_inside = sign[go], t_end[go], ends_inside[go]


def traverse(grid: OccGrid, origins: np.ndarray, dirs: np.ndarray,
             lengths: np.ndarray,
             occupied: Optional[np.ndarray] = None) -> np.ndarray:
    """Voxels that rays walk through (see :func:`walk_steps`).

    Args:
        grid (OccGrid): The grid; origins and directions are in its frame.
        origins (np.ndarray): Ray origins. Shape (R, 3) or (3,).
        dirs (np.ndarray): Unit ray directions. Shape (R, 3).
        lengths (np.ndarray): Ray lengths, metres. Shape (R,).
        occupied (np.ndarray, optional): Voxels that stop a ray. Shape
            (X, Y, Z). Defaults to None (rays run their full length).

    Returns:
        np.ndarray: Visited voxels. Shape (X, Y, Z), bool.
    """
    visited = np.zeros(int(np.prod(grid.shape)), dtype=bool)
    for flat, _ in walk_steps(grid, origins, dirs, lengths, occupied):
        visited[flat] = True
    return visited.reshape(grid.shape)


def pass_counts(grid: OccGrid, origins: np.ndarray, dirs: np.ndarray,
                lengths: np.ndarray) -> np.ndarray:
    """How many rays pass through every voxel without ending in it.

    A ray's own end voxel (where its return lies) is not counted, so that
    a surface voxel gets passes only from rays that went on beyond it.

    Args:
        grid (OccGrid): The grid; origins and directions are in its frame.
        origins (np.ndarray): Ray origins. Shape (R, 3) or (3,).
        dirs (np.ndarray): Unit ray directions. Shape (R, 3).
        lengths (np.ndarray): Ray lengths, metres. Shape (R,).

    Returns:
        np.ndarray: int64 counts. Shape (X, Y, Z).
    """
    passed = [flat[~ends] for flat, ends in walk_steps(grid, origins, dirs,
                                                       lengths)]
    size = int(np.prod(grid.shape))
    if not passed:
        return np.zeros(grid.shape, dtype=np.int64)
    return np.bincount(np.concatenate(passed), minlength=size).reshape(
        grid.shape)
