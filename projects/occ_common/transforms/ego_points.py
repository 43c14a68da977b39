"""Removal of the ego vehicle's own LiDAR returns.

A real nuScenes key frame holds about a quarter of its points on the car
itself (the roof rack and sensor mounts, the bonnet): 8,526 of the 34,688
points of the real sample in ``../shared`` lie inside the box below, all of
them within 2.1 m of the sensor, while the nearest point outside it is
3.5 m away. mmdet3d's ``remove_close`` (a 1 m sphere round the sensor,
applied to sweeps only) misses the bonnet and leaves the key frame as it
is; SurroundOcc's label generation cuts a 6 m cube round the sensor, which
also removes the road next to the car. A box round the car in the ego
frame removes exactly the car, in the key frame and in every sweep (each
in its own sensor frame, where the car is where it always is).
"""
from typing import Optional, Sequence

import numpy as np
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS

from .frames import PointsType, points_xyz

#: The nuScenes ego vehicle (a Renault Zoe: 4.084 m long, 1.945 m wide with
#: its mirrors, rear axle 0.657 m from the back, the LIDAR_TOP 1.84 m above
#: the ego origin on a roof rack) as ``(x0, y0, z0, x1, y1, z1)`` in the ego
#: frame (origin at the rear axle on the ground, x forward, y left), with
#: about 0.25 m to spare along x and 0.13 m along y, and up to 0.36 m above
#: the sensor for its housing. Below the ground there is nothing to keep.
NUSCENES_EGO_BOX = (-0.9, -1.1, -0.5, 3.7, 1.1, 2.2)


def check_ego_box(box: Sequence[float]) -> tuple:
    """``box`` as a tuple of 6 floats with min < max on every axis."""
    box = tuple(float(v) for v in box)
    if len(box) != 6 or not all(box[i] < box[i + 3] for i in range(3)):
        raise ValueError('ego_box must be (x0, y0, z0, x1, y1, z1) with '
                         f'x0 < x1, y0 < y1, z0 < z1, got {box}')
    return box


def in_ego_box(xyz: np.ndarray, lidar2ego: np.ndarray,
               box: Sequence[float]) -> np.ndarray:
    """Which sensor-frame points lie inside the ego box (bounds included).

    Args:
        xyz (np.ndarray): Points in the LiDAR sensor frame. Shape (P, 3).
        lidar2ego (np.ndarray): Sensor to ego frame. Shape (4, 4).
        box (Sequence[float]): ``(x0, y0, z0, x1, y1, z1)`` in the ego
            frame, metres.

    Returns:
        np.ndarray: Shape (P,), bool.
    """
    mat = np.asarray(lidar2ego, dtype=np.float64)
    ego = np.asarray(xyz, np.float64) @ mat[:3, :3].T + mat[:3, 3]
    box = np.asarray(box, dtype=np.float64)
    return np.all((ego >= box[:3]) & (ego <= box[3:]), axis=1)


@TRANSFORMS.register_module()
class RemoveEgoPoints(BaseTransform):
    """Drop the key-frame points that hit the ego vehicle itself.

    Apply it while the points are still in the LiDAR sensor frame (before
    sweeps are merged and before ``PointsToEgoFrame`` / BEV augmentation),
    after ``LoadLidarSegLabels`` if that is used: the labels of removed
    points are removed with them. Every column (intensity, ring index) of
    the kept points is kept as it is. ``LoadOccPointsFromMultiSweeps``
    takes the same ``ego_box`` for the sweeps.

    Args:
        ego_box (Sequence[float]): ``(x0, y0, z0, x1, y1, z1)`` in the ego
            frame, metres. Defaults to :data:`NUSCENES_EGO_BOX`.

    Required Keys:

    - points (BasePoints | np.ndarray): Key frame, LiDAR sensor frame.
    - lidar2ego (np.ndarray): Shape (4, 4).
    - pts_semantic_mask (np.ndarray, optional): Shape (P,).

    Modified Keys:

    - points, pts_semantic_mask: the points outside the box.

    Added Keys:

    - num_ego_points (int): How many points were removed.
    """

    def __init__(self,
                 ego_box: Sequence[float] = NUSCENES_EGO_BOX) -> None:
        self.ego_box = check_ego_box(ego_box)

    def transform(self, results: dict) -> dict:
        """Remove the ego returns of one sample.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The state without the ego returns.
        """
        # PointsToEgoFrame, OccBEVAug and the sweep merge leave these.
        if 'ori_lidar2ego' in results or 'bda_matrix' in results \
                or results.get('points_time_dim') is not None:
            raise ValueError(
                'RemoveEgoPoints needs the key frame in the LiDAR sensor '
                'frame: put it before LoadOccPointsFromMultiSweeps, '
                'PointsToEgoFrame and OccBEVAug (sample '
                f'{results.get("token", "?")})')
        points: PointsType = results['points']
        ego = in_ego_box(points_xyz(points), results['lidar2ego'],
                         self.ego_box)
        keep = ~ego
        results['points'] = points[keep]
        if 'pts_semantic_mask' in results:
            mask = np.asarray(results['pts_semantic_mask'])
            if len(mask) != len(ego):
                raise ValueError(
                    f'pts_semantic_mask has {len(mask)} labels but the key '
                    f'frame {results.get("lidar_path")} has {len(ego)} '
                    'points; load the labels before RemoveEgoPoints')
            results['pts_semantic_mask'] = mask[keep]
        results['num_ego_points'] = int(ego.sum())
        return results

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return f'{self.__class__.__name__}(ego_box={self.ego_box})'


def remove_ego_from_sweep(points: np.ndarray,
                          lidar2ego: Optional[np.ndarray],
                          box: Sequence[float]) -> np.ndarray:
    """The rows of a sweep (its own sensor frame) outside the ego box.

    Args:
        points (np.ndarray): Shape (P, C), x, y, z first.
        lidar2ego (np.ndarray): The sweep's sensor to ego transform.
            Shape (4, 4).
        box (Sequence[float]): See :class:`RemoveEgoPoints`.

    Returns:
        np.ndarray: Shape (P', C).

    Raises:
        ValueError: If ``lidar2ego`` is None.
    """
    if lidar2ego is None:
        raise ValueError('ego_box needs the lidar2ego of each sweep (or of '
                         'its key frame); the info has none')
    return points[~in_ego_box(points[:, :3], lidar2ego, box)]
