"""A 32-beam spinning LiDAR (Velodyne HDL-32E, as on nuScenes' LIDAR_TOP).

32 beams from -30.67 to +10.67 degrees elevation (1.33 degree spacing) spin
through ``azimuth_bins`` steps per sweep; nuScenes records 20 sweeps per
second. The sensor is mounted like nuScenes' LIDAR_TOP: 1.84 m above the
ground, rotated -90 degrees about z, so LiDAR x points to the ego's right
and y forward. A point is stored as ``x, y, z, intensity, ring`` in the
LiDAR frame of its own sweep (float32), exactly like nuScenes'
``.pcd.bin`` files; a LiDAR without ring index (``with_ring=False``, as
many drivers export) stores ``x, y, z, intensity``.

A sweep is captured at one instant (no rolling shutter): the whole sweep
uses the ego pose of its timestamp, which keeps ego-motion compensation
exact for the consumers of the data.
"""
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .geometry import make_transform, rot_z
from .raycast import TARGET_GROUND, cast_rays, cone_candidates
from .world import World

#: Beam elevations of the HDL-32E, degrees, lowest first (= ring index).
LIDAR_ELEVATIONS_DEG = np.linspace(-30.67, 10.67, 32)
#: LiDAR -> ego translation of nuScenes' LIDAR_TOP, metres.
LIDAR_TRANSLATION = (0.985, 0.0, 1.840)
#: LiDAR -> ego yaw of nuScenes' LIDAR_TOP, radians.
LIDAR_YAW = -np.pi / 2

# Reflectivity (0..255 scale) of every raw class: retro-reflective cones,
# barriers and lane paint return strongly, asphalt and foliage weakly.
_REFLECTIVITY = np.full(32, 20.0)
_REFLECTIVITY[[2, 3, 4, 6]] = 12.0     # pedestrians
_REFLECTIVITY[9] = 70.0                # barrier
_REFLECTIVITY[12] = 95.0               # traffic cone
_REFLECTIVITY[[14, 21]] = 30.0         # bicycle, motorcycle
_REFLECTIVITY[[15, 16, 17, 18, 22, 23]] = 35.0  # vehicles
_REFLECTIVITY[24] = 8.0                # driveable surface
_REFLECTIVITY[25] = 14.0               # other flat
_REFLECTIVITY[26] = 18.0               # sidewalk
_REFLECTIVITY[27] = 10.0               # terrain
_REFLECTIVITY[28] = 25.0               # manmade
_REFLECTIVITY[29] = 22.0               # static other
_REFLECTIVITY[30] = 15.0               # vegetation

#: ``Sweep.target`` of spurious returns (labelled lidarseg ``noise``).
TARGET_NOISE = -3


@dataclass
class Sweep:
    """One LiDAR sweep.

    Args:
        points (np.ndarray): ``x, y, z, intensity, ring`` (without ring
            index: ``x, y, z, intensity``) in the sweep's LiDAR frame,
            float32. Shape (N, 5) or (N, 4).
        raw_class (np.ndarray): Raw lidarseg class per point (0 for
            spurious returns), uint8. Shape (N,).
        target (np.ndarray): Box index per point, or
            :data:`.raycast.TARGET_GROUND` / :data:`TARGET_NOISE`.
            Shape (N,).
        origin (np.ndarray): Sensor position, global. Shape (3,).
        ray_dirs (np.ndarray): Unit direction of every fired ray, global.
            Shape (R, 3).
        ray_length (np.ndarray): Distance each ray travelled (its measured
            range, or the maximum range when nothing returned). Shape (R,).
    """
    points: np.ndarray
    raw_class: np.ndarray
    target: np.ndarray
    origin: np.ndarray
    ray_dirs: np.ndarray
    ray_length: np.ndarray


def make_lidar2ego(rng: Optional[np.random.Generator] = None) -> np.ndarray:
    """LIDAR_TOP -> ego transform, with an optional +-1 cm calibration
    jitter.

    Args:
        rng (np.random.Generator, optional): Jitter source.
            Defaults to None.

    Returns:
        np.ndarray: Transform. Shape (4, 4).
    """
    translation = np.asarray(LIDAR_TRANSLATION, dtype=np.float64)
    if rng is not None:
        translation = translation + rng.uniform(-0.01, 0.01, 3)
    return make_transform(rot_z(LIDAR_YAW), translation)


def beam_directions(azimuth_bins: int, phase: float = 0.0) -> np.ndarray:
    """Unit ray directions of one sweep in the LiDAR frame.

    Args:
        azimuth_bins (int): Azimuth steps per revolution.
        phase (float): Azimuth of the first step, radians. Defaults to 0.

    Returns:
        np.ndarray: Directions, ray ``ring * azimuth_bins + step``.
        Shape (32 * azimuth_bins, 3).
    """
    elevation = np.deg2rad(LIDAR_ELEVATIONS_DEG)[:, None]
    step = 2 * np.pi / azimuth_bins
    azimuth = phase + np.arange(azimuth_bins)[None] * step
    x = np.cos(elevation) * np.cos(azimuth)
    y = np.cos(elevation) * np.sin(azimuth)
    z = np.broadcast_to(np.sin(elevation), x.shape)
    return np.stack([x, y, z], axis=-1).reshape(-1, 3)


def scan_lidar(world: World, lidar2world: np.ndarray, t: float,
               azimuth_bins: int, rng: np.random.Generator,
               max_range: float = 70.0, min_range: float = 1.0,
               range_noise: float = 0.01, with_ring: bool = True) -> Sweep:
    """Captures one sweep of a world.

    Args:
        world (World): The scene.
        lidar2world (np.ndarray): LiDAR -> global at the sweep.
            Shape (4, 4).
        t (float): Seconds since the scene's first sweep.
        azimuth_bins (int): Azimuth steps per revolution.
        rng (np.random.Generator): Phase, range noise, spurious returns.
        max_range (float): Farthest return, metres. Defaults to 70.
        min_range (float): Nearest return, metres. Defaults to 1.
        range_noise (float): Range noise standard deviation, metres.
            Defaults to 0.01.
        with_ring (bool): Store each point's ring (beam) index as a fifth
            value, as nuScenes does. Defaults to True.

    Returns:
        Sweep: The sweep.
    """
    phase = rng.uniform(0, 2 * np.pi / azimuth_bins)
    local_dirs = beam_directions(azimuth_bins, phase)
    rotation, origin = lidar2world[:3, :3], lidar2world[:3, 3]
    dirs = local_dirs @ rotation.T
    boxes = world.boxes
    sensor_yaw = np.arctan2(rotation[1, 0], rotation[0, 0])
    candidates = cone_candidates(
        origin, boxes.corners_at(t), len(LIDAR_ELEVATIONS_DEG),
        np.deg2rad(LIDAR_ELEVATIONS_DEG), azimuth_bins, phase, sensor_yaw)
    hits = cast_rays(origin, dirs, boxes.centers_at(t), boxes.size,
                     boxes.yaw, candidates, t_min=min_range,
                     t_max=max_range)
    distance = hits.t.copy()
    target = hits.target.copy()
    raw = np.zeros(len(dirs), dtype=np.uint8)
    on_box = target >= 0
    raw[on_box] = boxes.raw_class[target[on_box]]
    on_ground = target == TARGET_GROUND
    ground_xy = origin[:2] + distance[on_ground, None] * dirs[on_ground, :2]
    raw[on_ground] = world.ground_class(ground_xy)
    # Spurious near returns (dust, rain drops), labelled lidarseg noise.
    noise_rate = 0.01 if world.is_rainy else 0.001
    spurious = rng.random(len(dirs)) < noise_rate
    spurious_range = rng.uniform(min_range, 12.0, len(dirs))
    spurious &= spurious_range < distance
    distance[spurious] = spurious_range[spurious]
    target[spurious] = TARGET_NOISE
    raw[spurious] = 0
    returned = np.isfinite(distance)
    measured = distance[returned] + rng.normal(0, range_noise,
                                               int(returned.sum()))
    measured = np.clip(measured, min_range, max_range)
    cos_incidence = np.abs(np.sum(hits.normal[returned] * dirs[returned],
                                  axis=1))
    cos_incidence[target[returned] == TARGET_NOISE] = 1.0
    intensity = _REFLECTIVITY[raw[returned]] * (0.4 + 0.6 * cos_incidence)
    intensity *= 1.0 + 0.1 * rng.standard_normal(len(intensity))
    intensity = np.clip(np.round(intensity), 0, 255)
    ring = np.repeat(np.arange(len(LIDAR_ELEVATIONS_DEG)), azimuth_bins)
    columns = [local_dirs[returned] * measured[:, None], intensity[:, None]]
    if with_ring:
        columns.append(ring[returned, None])
    points = np.concatenate(columns, axis=1).astype(np.float32)
    # Rays end at the measured range, so a point's voxel is always one its
    # ray reached.
    ray_length = np.full(len(dirs), max_range)
    ray_length[returned] = measured
    return Sweep(points=points, raw_class=raw[returned],
                 target=target[returned], origin=origin, ray_dirs=dirs,
                 ray_length=ray_length)
