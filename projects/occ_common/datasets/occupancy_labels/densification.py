"""Densification: the parts of surfaces and solids the LiDAR missed.

* :func:`fill_ground`: a column of the grid without anything near the
  ground gets the ground layer (height and class) of the nearest column
  whose ground was observed, within a radius. Ground is continuous where
  nothing stands on it; the 32-beam LiDAR leaves rings of unobserved
  ground between its beams' circles, and all of it beyond ~30 m.
* :func:`object_hull` / :func:`fill_hull`: an object's voxels inside the
  convex hull of its accumulated box-frame points become the object: its
  interior is never hit, yet it is occupied. Convex hulls suit vehicles,
  barriers, cones and people seen from around; an object seen from one
  side only gets a thin hull.
"""
from typing import Optional

import numpy as np

from ...geometry.voxel_walk import OccGrid
from .box_frame import to_box_frame
from .voxelization import EMPTY

#: Occupancy classes of the ground (driveable surface, other flat,
#: sidewalk, terrain).
GROUND_LABELS = (11, 12, 13, 14)


def fill_ground(labels: np.ndarray, voxel_size: float,
                radius: float) -> np.ndarray:
    """Fill unobserved ground (see the module docstring).

    A column is filled at layer ``g`` (its nearest observed ground
    column's lowest ground voxel) when it has no occupied voxel at or
    below ``g + 1``: a car's body or a trunk keeps its column, a tree's
    crown does not.

    Args:
        labels (np.ndarray): uint8 classes, :data:`.EMPTY` where empty;
            modified in place. Shape (X, Y, Z).
        voxel_size (float): Voxel edge, metres.
        radius (float): Farthest observed ground column to copy from,
            metres; 0 leaves the grid as it is.

    Returns:
        np.ndarray: ``labels``.
    """
    if radius <= 0:
        return labels
    from scipy.ndimage import distance_transform_edt
    ground = np.isin(labels, GROUND_LABELS)
    observed = ground.any(axis=2)
    if not observed.any():
        return labels
    num_z = labels.shape[2]
    # The lowest ground voxel of each observed column.
    layer = np.where(observed, np.argmax(ground, axis=2), 0)
    dist, (ix, iy) = distance_transform_edt(~observed, return_indices=True)
    source_layer = layer[ix, iy]
    source_class = np.take_along_axis(labels[ix, iy],
                                      source_layer[..., None], axis=2)[..., 0]
    occupied = labels != EMPTY
    # Occupied at or below g + 1: the first occupied layer is <= g + 1.
    first = np.where(occupied.any(axis=2), np.argmax(occupied, axis=2),
                     num_z)
    fill = (~observed) & (dist * voxel_size <= radius) & (
        first > source_layer + 1)
    x, y = np.nonzero(fill)
    labels[x, y, source_layer[fill]] = source_class[fill]
    return labels


def object_hull(points: np.ndarray) -> Optional[np.ndarray]:
    """Half-space equations of the convex hull of box-frame points.

    Args:
        points (np.ndarray): Shape (M, 3).

    Returns:
        np.ndarray, optional: Rows ``(a, b, c, d)`` with ``a x + b y + c z
        + d <= 0`` inside, Shape (F, 4); None when the points span no
        volume (fewer than 4, or all on a plane or line).
    """
    if len(points) < 4:
        return None
    from scipy.spatial import ConvexHull, QhullError

    # Points closer than 5 cm add nothing to a hull but time.
    points = np.unique(np.round(points / 0.05), axis=0) * 0.05
    try:
        return ConvexHull(points).equations
    except (QhullError, ValueError):
        return None


def fill_hull(labels: np.ndarray, grid: OccGrid, global2grid: np.ndarray,
              hull: np.ndarray, center: np.ndarray, yaw: float,
              half_extent: np.ndarray, label: int) -> None:
    """Set the empty voxels whose centre lies in an object's hull.

    Args:
        labels (np.ndarray): uint8 classes, modified in place.
            Shape (X, Y, Z).
        grid (OccGrid): Its grid.
        global2grid (np.ndarray): Global -> grid frame. Shape (4, 4).
        hull (np.ndarray): :func:`object_hull`. Shape (F, 4).
        center (np.ndarray): The box's centre at the key frame, global.
            Shape (3,).
        yaw (float): Its heading.
        half_extent (np.ndarray): Half length, width, height of a box
            holding the hull. Shape (3,).
        label (int): The object's class.
    """
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1)
                      for z in (-1, 1)], dtype=np.float64)
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    corners = (signs * half_extent) @ rot.T + center
    corners = corners @ global2grid[:3, :3].T + global2grid[:3, 3]
    vs = grid.voxel_size
    lo = np.maximum(np.floor((corners.min(0) - grid.lower) / vs), 0)
    hi = np.minimum(np.ceil((corners.max(0) - grid.lower) / vs),
                    grid.shape)
    lo, hi = lo.astype(int), hi.astype(int)
    if (lo >= hi).any():
        return
    ijk = np.stack(np.meshgrid(*[np.arange(a, b) for a, b in zip(lo, hi)],
                               indexing='ij'), axis=-1).reshape(-1, 3)
    centers = np.asarray(grid.lower) + (ijk + 0.5) * vs
    grid2global = np.linalg.inv(global2grid)
    world = centers @ grid2global[:3, :3].T + grid2global[:3, 3]
    local = to_box_frame(world, center, yaw)
    inside = (local @ hull[:, :3].T + hull[:, 3] <= 1e-9).all(axis=1)
    ijk = ijk[inside]
    cells = labels[ijk[:, 0], ijk[:, 1], ijk[:, 2]]
    empty = cells == EMPTY
    labels[ijk[empty, 0], ijk[empty, 1], ijk[empty, 2]] = label
