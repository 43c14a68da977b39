"""Misalignment between the sensors: calibration the model is told that is
wrong in space, or LiDAR data that is late.

Both leave the measured data of the other sensor alone, so the model's
fusion is what is tested: the images and points are true, only what links
them (the camera extrinsics, the time) is off.
"""
from typing import Tuple

import numpy as np

from ..frames import refresh_lidar2img, transform_points
from ..points_loading import LoadOccPointsFromMultiSweeps


def random_unit_vector(rng: np.random.Generator) -> np.ndarray:
    """A direction drawn uniformly on the sphere. Shape (3,)."""
    vec = rng.normal(size=3)
    return vec / np.linalg.norm(vec)


def rotation_about(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation by ``angle`` radians about unit ``axis``.

    Returns:
        np.ndarray: Shape (3, 3).
    """
    x, y, z = axis
    skew = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return (np.eye(3) + np.sin(angle) * skew +
            (1 - np.cos(angle)) * skew @ skew)


def rigid_offset(angle_deg: float, shift_m: float,
                 rng: np.random.Generator) -> np.ndarray:
    """A rotation of exactly ``angle_deg`` about a random axis and a shift
    of exactly ``shift_m`` in a random direction. Shape (4, 4)."""
    offset = np.eye(4)
    offset[:3, :3] = rotation_about(random_unit_vector(rng),
                                    np.deg2rad(angle_deg))
    offset[:3, 3] = shift_m * random_unit_vector(rng)
    return offset


def spatial_misalignment(results: dict, level: Tuple[float, float],
                         rng: np.random.Generator) -> None:
    """Every camera's extrinsics, as the model is told them, are off by its
    own rigid offset ``D`` (rotation ``angle_deg`` about a random axis
    through the camera, shift ``shift_m``): ``lidar2cam <- D @ lidar2cam``,
    ``cam2ego <- cam2ego @ inv(D)`` and ``lidar2img`` recomputed. The
    images and points stay true: the model projects between them with the
    wrong pose, as after a camera was knocked or its calibration drifted.

    Args:
        level (tuple): ``(angle_deg, shift_m)``.
    """
    lidar2cam = np.asarray(results['lidar2cam'], np.float64).copy()
    offsets = np.stack([rigid_offset(*level, rng)
                        for _ in range(len(lidar2cam))])
    results['lidar2cam'] = offsets @ lidar2cam
    if 'cam2ego' in results:
        results['cam2ego'] = np.asarray(results['cam2ego'],
                                        np.float64) @ np.linalg.inv(offsets)
    refresh_lidar2img(results)


def temporal_misalignment(results: dict, delay_sweeps: int,
                          rng: np.random.Generator) -> None:
    """The LiDAR is late: its data, key frame and sweeps, are the ones it
    had ``delay_sweeps`` sweeps ago (50 ms each in nuScenes), handed over
    as current while the cameras are on time.

    The whole cloud moves into the sensor pose of the sweep that many
    steps back (``inv(sweep2key)``, the exact motion of the ego since), so
    the static world sits where a late LiDAR saw it; moving objects keep
    their current place (the ego's motion, not theirs, is what is late),
    and the cloud keeps its density. A sample with fewer sweeps uses its
    oldest; one without any (a scene's first key frame) stays as it is.
    ``corruption_delay_s`` records the delay applied.
    """
    # Newest first, whatever order the info file lists them in.
    sweeps = sorted(results.get('lidar_sweeps') or [],
                    key=lambda s: -float(s['timestamp']))
    results['corruption_delay_s'] = 0.0
    if not sweeps:
        return
    sweep = sweeps[min(int(delay_sweeps), len(sweeps)) - 1]
    sweep2key = LoadOccPointsFromMultiSweeps.sweep_to_key(sweep)
    key2sweep = np.linalg.inv(sweep2key)
    # In the working frame W (= L, or the ego's E once the points moved
    # there): the sweep's pose is W <- L <- sweep, i.e. conjugated.
    to_work = np.eye(4)
    if 'ori_lidar2ego' in results:
        to_work = np.asarray(results['ori_lidar2ego'], np.float64)
    late = to_work @ key2sweep @ np.linalg.inv(to_work)
    results['points'] = transform_points(results['points'], late)
    results['corruption_delay_s'] = float(results['timestamp'] -
                                          sweep['timestamp'])
