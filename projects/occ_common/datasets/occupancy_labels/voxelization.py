"""Points into a label format's voxel grid.

A key frame's label grid is built in the frame of its format (the ego
frame for Occ3D, the LiDAR frame for SurroundOcc; :func:`format_grid`):
the static points and the objects' points placed at the key frame's boxes
are moved there and every voxel takes the majority class of its points,
objects first (:func:`.semantics.vote`). The grid holds classes 0..16 and
:data:`EMPTY` for voxels without a point.
"""
from typing import List, Tuple

import numpy as np

from ...geometry.voxel_walk import OccGrid
from ..occ_formats import OCC_FORMATS
from .semantics import vote

#: Label grids' marker of voxels without a point.
EMPTY = 255


def format_grid(name: str) -> OccGrid:
    """The voxel grid of a label format (``'occ3d'`` or
    ``'surroundocc'``), in that format's frame."""
    spec = OCC_FORMATS[name]
    if len(set(spec.voxel_size)) != 1:
        raise ValueError(f'{name}: expected cubic voxels, got '
                         f'{spec.voxel_size}.')
    return OccGrid(tuple(spec.point_cloud_range[:3]),
                   float(spec.voxel_size[0]), tuple(spec.grid_size))


def grid_corners(grid: OccGrid, grid2global: np.ndarray) -> np.ndarray:
    """The 8 corners of a grid, global. Shape (8, 3)."""
    lo, hi = np.asarray(grid.lower), grid.upper
    corners = np.array([[x, y, z] for x in (lo[0], hi[0])
                        for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return corners @ grid2global[:3, :3].T + grid2global[:3, 3]


def label_grid(grid: OccGrid, layers: List[Tuple[np.ndarray, np.ndarray]]
               ) -> np.ndarray:
    """Voxel classes from layers of labelled points, later layers winning.

    Args:
        grid (OccGrid): The grid.
        layers (List[Tuple[np.ndarray, np.ndarray]]): ``(points, labels)``
            in the grid's frame, e.g. ``[static, objects]``: a voxel takes
            the majority class of the last layer that has points in it.
            Shape (N, 3) and (N,) each.

    Returns:
        np.ndarray: uint8 classes 0..16, :data:`EMPTY` elsewhere.
        Shape (X, Y, Z).
    """
    out = np.full(int(np.prod(grid.shape)), EMPTY, dtype=np.uint8)
    for points, labels in layers:
        ijk, inside = grid.voxel_index(points)
        voxels, classes = vote(grid.flat_index(ijk), labels[inside])
        out[voxels] = classes
    return out.reshape(grid.shape)
