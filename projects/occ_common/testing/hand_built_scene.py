"""Hand-built one-scene nuScenes roots for the occupancy label generator.

A test states every return of every sweep, the ego poses and the boxes;
:func:`write_hand_built_scene` writes them as nuScenes tables and files
(nuscenes-devkit opens them), so that the generator's answer can be
checked against one worked out by hand::

    root = write_hand_built_scene(str(tmp_path), [
        HandSweep(time=0.0, ego_xy=(0, 0), points=wall_points, key=True,
                  raw_class=28),
        ...])

The LiDAR sits at :data:`LIDAR_TRANSLATION` in the ego frame without
rotation (its frame is the ego's, raised), and an optional front camera
at :data:`CAMERA_TRANSLATION` looks along the ego's x axis.
"""
import os
import os.path as osp
from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Tuple

import cv2
import numpy as np

from ..datasets.nuscenes_classes import LIDARSEG_RAW_CLASS_NAMES
from ..synthetic.geometry import make_transform, rot_z, yaw_quaternion
from ..synthetic.tables import NuScenesTables, make_token

#: LIDAR_TOP -> ego translation of hand-built scenes (no rotation).
LIDAR_TRANSLATION = (0.0, 0.0, 1.8)
#: CAM_FRONT -> ego translation; it looks along ego +x.
CAMERA_TRANSLATION = (1.5, 0.2, 1.5)
#: CAM_FRONT's image size and pixel matrix (a 90 degree field of view).
CAMERA_SIZE = (64, 36)
CAMERA_INTRINSIC = ((32.0, 0.0, 32.0), (0.0, 32.0, 18.0), (0.0, 0.0, 1.0))

_SEED = 7
_BASE_US = 1_600_000_000_000_000


@dataclass
class HandSweep:
    """One sweep of a hand-built scene.

    Args:
        time (float): Seconds since the scene's start.
        ego_xy (Tuple[float, float]): Ego position (z = 0, yaw 0), global.
        points (np.ndarray): Returns in the global frame. Shape (N, 3).
        key (bool): Whether it is a key frame (gets a sample).
            Defaults to False.
        raw_class (int, optional): lidarseg class of every return (key
            frames only); None writes no lidarseg. Defaults to None.
        rings (np.ndarray, optional): Ring index of every return.
            Shape (N,). Defaults to zeros.
    """
    time: float
    ego_xy: Tuple[float, float]
    points: np.ndarray
    key: bool = False
    raw_class: Optional[int] = None
    rings: Optional[np.ndarray] = None


@dataclass
class HandBox:
    """One annotated object: its box at every key frame, in order.

    Args:
        category (str): nuScenes category, e.g. ``vehicle.car``.
        size (Tuple[float, float, float]): Length, width, height.
        centers (Sequence[Tuple[float, float, float]]): Global centres,
            one per key frame.
        yaw (float): Heading (the same at every key frame).
    """
    category: str
    size: Tuple[float, float, float]
    centers: Sequence[Tuple[float, float, float]] = field(
        default_factory=list)
    yaw: float = 0.0


def write_hand_built_scene(root: str, sweeps: List[HandSweep],
                           boxes: Sequence[HandBox] = (),
                           camera: bool = False,
                           version: str = 'v1.0-mini') -> str:
    """Write a one-scene nuScenes root (see the module docstring).

    Args:
        root (str): Folder to write (created).
        sweeps (List[HandSweep]): The LiDAR sweeps, in time order; at
            least one key frame.
        boxes (Sequence[HandBox]): Objects annotated at every key frame.
        camera (bool): Add CAM_FRONT to every key frame (its image file
            is not written: the label generator reads only its
            calibration). Defaults to False.
        version (str): Table folder. Defaults to 'v1.0-mini'.

    Returns:
        str: ``root``.
    """
    tables = NuScenesTables(_SEED)
    lidar2ego = make_transform(np.eye(3), LIDAR_TRANSLATION)
    channels = [('LIDAR_TOP', 'lidar', lidar2ego, None)]
    if camera:
        # Camera x right (ego -y), y down (ego -z), z forward (ego x).
        cam_rot = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0],
                            [0.0, -1.0, 0.0]])
        channels.append(('CAM_FRONT', 'camera',
                         make_transform(cam_rot, CAMERA_TRANSLATION),
                         np.asarray(CAMERA_INTRINSIC)))
    for channel, modality, sensor2ego, intrinsic in channels:
        tables.add_sensor(make_token(_SEED, 'sensor', channel), channel,
                          modality)
        tables.add_calibrated_sensor(
            make_token(_SEED, 'calib', channel),
            make_token(_SEED, 'sensor', channel), sensor2ego, intrinsic)
    log, scene = make_token(_SEED, 'log'), make_token(_SEED, 'scene')
    tables.add('log', token=log, logfile='hand-built', vehicle='hand',
               date_captured='2020-09-13', location='singapore-onenorth')
    # nuscenes-devkit wants a map raster per log (it is never read here).
    os.makedirs(osp.join(root, 'maps'), exist_ok=True)
    cv2.imwrite(osp.join(root, 'maps', 'prior.png'),
                np.zeros((2, 2), np.uint8))
    tables.add('map', token=make_token(_SEED, 'map'), log_tokens=[log],
               category='semantic_prior', filename='maps/prior.png')
    keys = [i for i, s in enumerate(sweeps) if s.key]
    samples = [make_token(_SEED, 'sample', k) for k in range(len(keys))]
    lidar_sd = [make_token(_SEED, 'lidar', i) for i in range(len(sweeps))]
    os.makedirs(osp.join(root, 'sweeps', 'LIDAR_TOP'), exist_ok=True)
    os.makedirs(osp.join(root, 'samples', 'LIDAR_TOP'), exist_ok=True)
    os.makedirs(osp.join(root, 'lidarseg', version), exist_ok=True)
    for i, sweep in enumerate(sweeps):
        stamp = _BASE_US + int(round(sweep.time * 1e6))
        ego2global = make_transform(rot_z(0.0), [*sweep.ego_xy, 0.0])
        global2lidar = np.linalg.inv(ego2global @ lidar2ego)
        local = np.asarray(sweep.points, np.float64).reshape(-1, 3)
        local = local @ global2lidar[:3, :3].T + global2lidar[:3, 3]
        rings = np.zeros(len(local)) if sweep.rings is None else sweep.rings
        data = np.concatenate([local, np.zeros((len(local), 1)),
                               np.asarray(rings, np.float64)[:, None]],
                              axis=1).astype(np.float32)
        folder = 'samples' if sweep.key else 'sweeps'
        filename = f'{folder}/LIDAR_TOP/hand__LIDAR_TOP__{stamp}.pcd.bin'
        data.tofile(osp.join(root, filename))
        # The nearest key frame's sample, as nuScenes links sweeps.
        nearest = int(np.argmin([abs(sweeps[k].time - sweep.time)
                                 for k in keys]))
        ego_token = make_token(_SEED, 'ego', i)
        tables.add_ego_pose(ego_token, stamp, ego2global)
        tables.add('sample_data', token=lidar_sd[i],
                   sample_token=samples[nearest], ego_pose_token=ego_token,
                   calibrated_sensor_token=make_token(_SEED, 'calib',
                                                      'LIDAR_TOP'),
                   timestamp=stamp, filename=filename, fileformat='pcd',
                   is_key_frame=sweep.key, height=0, width=0,
                   prev=lidar_sd[i - 1] if i else '',
                   next=lidar_sd[i + 1] if i + 1 < len(sweeps) else '')
        if sweep.key and sweep.raw_class is not None:
            seg = f'lidarseg/{version}/{lidar_sd[i]}_lidarseg.bin'
            np.full(len(local), sweep.raw_class, np.uint8).tofile(
                osp.join(root, seg))
            tables.add('lidarseg', token=lidar_sd[i],
                       sample_data_token=lidar_sd[i], filename=seg)
        if sweep.key and camera:
            k = keys.index(i)
            tables.add('sample_data', token=make_token(_SEED, 'cam', k),
                       sample_token=samples[k], ego_pose_token=ego_token,
                       calibrated_sensor_token=make_token(_SEED, 'calib',
                                                          'CAM_FRONT'),
                       timestamp=stamp, fileformat='jpg', is_key_frame=True,
                       filename=f'samples/CAM_FRONT/hand__{stamp}.jpg',
                       width=CAMERA_SIZE[0], height=CAMERA_SIZE[1],
                       prev='', next='')
    for k, index in enumerate(keys):
        tables.add('sample', token=samples[k], scene_token=scene,
                   timestamp=_BASE_US + int(round(sweeps[index].time * 1e6)),
                   prev=samples[k - 1] if k else '',
                   next=samples[k + 1] if k + 1 < len(keys) else '')
    _annotate(tables, boxes, samples)
    tables.add('scene', token=scene, log_token=log, nbr_samples=len(keys),
               first_sample_token=samples[0], last_sample_token=samples[-1],
               name='scene-0001', description='hand-built')
    tables.write(osp.join(root, version))
    if not tables.tables['lidarseg']:
        os.remove(osp.join(root, version, 'lidarseg.json'))
    return root


def _annotate(tables: NuScenesTables, boxes: Sequence[HandBox],
              samples: List[str]) -> None:
    for b, box in enumerate(boxes):
        tokens = [make_token(_SEED, 'ann', b, k) for k in range(len(samples))]
        instance = make_token(_SEED, 'instance', b)
        for k, center in enumerate(box.centers):
            length, width, height = box.size
            tables.add('sample_annotation', token=tokens[k],
                       sample_token=samples[k], instance_token=instance,
                       visibility_token='4', attribute_tokens=[],
                       translation=[float(v) for v in center],
                       size=[width, length, height],
                       rotation=[float(v) for v in yaw_quaternion(box.yaw)],
                       prev=tokens[k - 1] if k else '',
                       next=tokens[k + 1] if k + 1 < len(box.centers)
                       else '', num_lidar_pts=1, num_radar_pts=0)
        tables.add('instance', token=instance,
                   category_token=tables.category_token(
                       LIDARSEG_RAW_CLASS_NAMES.index(box.category)),
                   nbr_annotations=len(box.centers),
                   first_annotation_token=tokens[0],
                   last_annotation_token=tokens[len(box.centers) - 1])
