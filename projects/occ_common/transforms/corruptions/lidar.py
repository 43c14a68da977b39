"""LiDAR failures of a loaded sample: fewer beams, fewer points, fog,
crosstalk, no LiDAR at all.

Each function changes the pipeline state of one sample in place, after the
key frame and its sweeps are loaded (and the ego's returns removed):
``points`` (mmdet3d ``BasePoints`` or an array, Shape (P, C): x, y, z,
intensity, ...) in the working frame. ``pts_semantic_mask`` (P,), where
present, keeps one label per point: dropped with its point, 255 (ignored)
for a point that crosstalk moved.

Ranges are measured from the sensor: the working frame's origin, or
``ori_lidar2ego``'s translation once the points are in the ego frame.
"""
from typing import Optional

import numpy as np
import torch
from mmdet3d.structures.points import BasePoints

from ...datasets.occ_formats import IGNORE_INDEX
from ..points_loading import RING_COLUMN

#: Column of the intensity in every points layout of this library.
INTENSITY_COLUMN = 3


def points_array(results: dict) -> np.ndarray:
    """The points of ``results`` as an array (a view of the tensor).

    Returns:
        np.ndarray: Shape (P, C), float32.
    """
    points = results.get('points')
    if points is None:
        raise ValueError(
            f'sample {results.get("token", "?")}: OccCorruption needs the '
            'loaded points (results["points"]); place it after the points '
            'loaders')
    return points.tensor.numpy() if isinstance(points, BasePoints) \
        else np.asarray(points)


def set_points(results: dict, array: np.ndarray) -> None:
    """Replace the points by ``array`` Shape (P', C), in their type."""
    points = results['points']
    if isinstance(points, BasePoints):
        results['points'] = type(points)(
            torch.from_numpy(np.ascontiguousarray(array)),
            points_dim=array.shape[1],
            attribute_dims=points.attribute_dims)
    else:
        results['points'] = array


def keep_points(results: dict, keep: np.ndarray) -> None:
    """Keep the points where ``keep`` (bool, Shape (P,)) holds, with their
    labels and ring indices."""
    set_points(results, points_array(results)[keep])
    for key in ('pts_semantic_mask', 'points_ring'):
        if key in results:
            results[key] = np.asarray(results[key])[keep]


def sensor_origin(results: dict) -> np.ndarray:
    """Where the LiDAR is in the working frame. Shape (3,)."""
    if 'ori_lidar2ego' in results:  # points already in the ego frame
        return np.asarray(results['ori_lidar2ego'], np.float64)[:3, 3]
    return np.zeros(3)


def point_ring(results: dict) -> np.ndarray:
    """The beam (ring) index of every point. Shape (P,), int64.

    From ``points_ring`` (``LoadOccPointsFromMultiSweeps(record_ring=
    True)``), or from the file's ring column while no sweeps are merged
    (``LoadOccPointsFromFile`` with ``use_dim`` keeping column 4).
    """
    if 'points_ring' in results:
        return np.asarray(results['points_ring']).astype(np.int64)
    data = points_array(results)
    if 'points_time_dim' not in results and data.shape[1] > RING_COLUMN:
        return data[:, RING_COLUMN].astype(np.int64)
    raise ValueError(
        f'sample {results.get("token", "?")}: beam_reduction needs the '
        'ring index of every point; the sweeps loader replaced it with the '
        'time lag. Set LoadOccPointsFromMultiSweeps(record_ring=True) '
        '(tools/analysis_tools/robustness.py does).')


def beam_reduction(results: dict, step: int,
                   rng: Optional[np.random.Generator] = None) -> None:
    """Keep the beams whose ring index is a multiple of ``step`` (16, 11,
    8, 6, 4 of a 32-beam LiDAR for steps 2, 3, 4, 6, 8), key frame and
    sweeps alike."""
    keep_points(results, point_ring(results) % int(step) == 0)


def point_reduction(results: dict, share: float,
                    rng: np.random.Generator) -> None:
    """Drop ``round(share * P)`` points, the first of a random order
    (those of a lower share among them)."""
    num = len(points_array(results))
    keep = np.zeros(num, bool)
    keep[rng.permutation(num)[:num - int(round(share * num))]] = True
    keep_points(results, keep)


def lidar_fog(results: dict, alpha: float,
              rng: np.random.Generator) -> None:
    """Beer-Lambert attenuation of fog (or rain) with extinction
    coefficient ``alpha`` (1/m): a return at range r survives with
    probability ``exp(-2 alpha r)`` (the pulse crosses the fog twice), and
    the survivors' intensity is scaled by that factor."""
    data = points_array(results)
    ranges = np.linalg.norm(
        data[:, :3].astype(np.float64) - sensor_origin(results), axis=1)
    transmission = np.exp(-2.0 * alpha * ranges)
    keep = rng.random(len(data)) < transmission
    if data.shape[1] > INTENSITY_COLUMN:
        data[:, INTENSITY_COLUMN] *= transmission.astype(data.dtype)
    keep_points(results, keep)


def lidar_crosstalk(results: dict, share: float,
                    rng: np.random.Generator) -> None:
    """Crosstalk (light of another LiDAR read as a return): a share of the
    points, the first of a random order, is displaced by N(0, 3 m) per
    axis, as in Dong et al. (CVPR 2023); their labels become ignored."""
    data = points_array(results)
    count = int(round(share * len(data)))
    hit = rng.permutation(len(data))[:count]
    data[hit, :3] += rng.normal(0.0, 3.0, (count, 3)).astype(data.dtype)
    if 'pts_semantic_mask' in results:
        results['pts_semantic_mask'] = np.asarray(
            results['pts_semantic_mask']).copy()
        results['pts_semantic_mask'][hit] = IGNORE_INDEX


def lidar_missing(results: dict, prob: float,
                  rng: np.random.Generator) -> None:
    """With probability ``prob`` the sample has no LiDAR points at all."""
    num = len(points_array(results))
    if rng.random() < prob:
        keep_points(results, np.zeros(num, bool))
