"""Classes of points and voxels.

* Static points take their lidarseg class where their sweep has one
  (nuScenes-lidarseg labels key frames only), else the class of the
  nearest labelled static point within a radius, else ``others``: a
  dataset without lidarseg gets ``others`` for everything that is not in
  a box.
* Object points take the class of their box's category.
* A voxel takes the majority class of its points (:func:`vote`); objects
  win over the static scene, as small things are drawn over the ground
  in the exact labels.

Classes here are the 16 occupancy classes 1..16 and 0 (``others`` /
ignored raw classes), mapped from the raw lidarseg classes with the
challenge table :data:`..nuscenes_classes.LIDARSEG_RAW_TO_OCC16`.
"""
from typing import Tuple

import numpy as np

from ..nuscenes_classes import LIDARSEG_RAW_CLASS_NAMES, LIDARSEG_RAW_TO_OCC16

#: Classes a voxel can take (0 others, 1..16).
NUM_LABELS = 17


def category_label(category: str) -> int:
    """Occupancy class (0..16) of a nuScenes category name (0 for a name
    that is no lidarseg class)."""
    if category not in LIDARSEG_RAW_CLASS_NAMES:
        return 0
    return int(LIDARSEG_RAW_TO_OCC16[LIDARSEG_RAW_CLASS_NAMES.index(
        category)])


def static_labels(points: np.ndarray, raw: np.ndarray,
                  radius: float) -> np.ndarray:
    """Occupancy class of every static point.

    Args:
        points (np.ndarray): Global positions. Shape (S, 3).
        raw (np.ndarray): Raw lidarseg class, -1 where unlabelled.
            Shape (S,).
        radius (float): Farthest labelled neighbour to copy from, metres.

    Returns:
        np.ndarray: uint8 classes 0..16. Shape (S,).
    """
    labelled = raw >= 0
    out = np.zeros(len(points), dtype=np.uint8)
    out[labelled] = LIDARSEG_RAW_TO_OCC16[raw[labelled]]
    todo = ~labelled
    if not labelled.any() or not todo.any():
        return out
    from scipy.spatial import cKDTree
    tree = cKDTree(points[labelled])
    dist, nearest = tree.query(points[todo], distance_upper_bound=radius)
    found = np.isfinite(dist)
    copied = np.zeros(int(todo.sum()), dtype=np.uint8)
    copied[found] = out[labelled][nearest[found]]
    out[todo] = copied
    return out


def vote(flat: np.ndarray,
         labels: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The majority class of the points in each voxel.

    Ties go to the higher class index (deterministic, and rarely more
    than a point apart).

    Args:
        flat (np.ndarray): Flat voxel index of every point. Shape (N,).
        labels (np.ndarray): Class of every point, 0..16. Shape (N,).

    Returns:
        tuple[np.ndarray, np.ndarray]: The occupied voxels' flat indices,
        ascending, and their classes (uint8). Shape (V,) each.
    """
    if not len(flat):
        return np.zeros(0, np.int64), np.zeros(0, np.uint8)
    keys, counts = np.unique(
        np.asarray(flat, np.int64) * NUM_LABELS + labels, return_counts=True)
    voxels = keys // NUM_LABELS
    # Sorted by voxel, then count: the last row of a voxel is its majority.
    order = np.lexsort((counts, voxels))
    last = np.append(voxels[order][1:] != voxels[order][:-1], True)
    chosen = order[last]
    return voxels[chosen], (keys[chosen] % NUM_LABELS).astype(np.uint8)
