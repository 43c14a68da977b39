"""What a nuScenes-format scene's files say: sweeps, key frames, tracks.

:func:`read_scene` walks one scene with nuscenes-devkit and gathers all
that the label generator reads, and nothing else: the LiDAR sweeps of the
whole scene (key frames and the sweeps between them, in time order, with
their sensor poses and lidarseg files where there are any), the key frames
(ego pose, LiDAR calibration, the cameras' poses, intrinsics and image
sizes) and one :class:`Track` per annotated instance (its box at every key
frame it is annotated in).

Conventions are nuScenes': poses map sensor (or ego) to parent
coordinates; a box's ``size`` is width, length, height and its rotation a
quaternion; here a box is kept as centre, yaw and ``(length, width,
height)``, so that its frame's x runs along the heading.
"""
import os.path as osp
import re
from dataclasses import dataclass, field
from typing import Dict, List, Optional

import numpy as np

from ..converters.nuscenes_occ_converter import pose_matrix
from ..info_format import NUM_POINT_FEATS
from ..nuscenes_classes import LIDARSEG_RAW_CLASS_NAMES

#: Raw lidarseg class of points that are no object (spurious returns).
RAW_NOISE = LIDARSEG_RAW_CLASS_NAMES.index('noise')
#: Raw lidarseg class of returns from the ego vehicle itself.
RAW_EGO = LIDARSEG_RAW_CLASS_NAMES.index('vehicle.ego')
#: Raw lidarseg classes of the ground (``flat.*``).
RAW_GROUND = tuple(i for i, name in enumerate(LIDARSEG_RAW_CLASS_NAMES)
                   if name.startswith('flat.'))

_PLAIN = re.compile(r'^[0-9A-Za-z_+-][0-9A-Za-z_.+-]*$')


def plain_name(value: str, what: str) -> str:
    """``value`` if it can name a file or folder inside the output folder:
    letters, digits, ``_ - + .``, not starting with a dot, as nuScenes
    tokens, scene names and sweep file names are.

    Args:
        value (str): A token or scene name from the tables.
        what (str): What it is, for the error message.

    Returns:
        str: ``value``.

    Raises:
        ValueError: If it holds anything else (a path separator, ``..``,
            spaces), which would write outside the output folder.
    """
    if not isinstance(value, str) or not _PLAIN.match(value):
        raise ValueError(f'{what} {value!r} cannot name an output file: '
                         'expected letters, digits and "_-+." only, not '
                         'starting with ".".')
    return value


@dataclass
class Sweep:
    """One LiDAR sweep of a scene.

    Args:
        token (str): Its ``sample_data`` token.
        timestamp (float): Seconds.
        path (str): The ``.pcd.bin`` file.
        lidar2global (np.ndarray): Sensor -> global. Shape (4, 4).
        ego2global (np.ndarray): Ego -> global at the sweep. Shape (4, 4).
        lidarseg_path (str, optional): Its lidarseg labels (key frames of
            nuScenes-lidarseg), None without.
    """
    token: str
    timestamp: float
    path: str
    lidar2global: np.ndarray
    ego2global: np.ndarray
    lidarseg_path: Optional[str] = None


@dataclass
class CameraView:
    """One camera of a key frame.

    Args:
        name (str): Channel, e.g. ``CAM_FRONT``.
        cam2global (np.ndarray): Camera -> global. Shape (4, 4).
        intrinsic (np.ndarray): Pixel matrix. Shape (3, 3).
        width (int): Image width, pixels.
        height (int): Image height, pixels.
    """
    name: str
    cam2global: np.ndarray
    intrinsic: np.ndarray
    width: int
    height: int


@dataclass
class KeyFrame:
    """One annotated sample of a scene.

    Args:
        token (str): Sample token.
        sweep_index (int): Index of its LiDAR sweep in
            :attr:`SceneSequence.sweeps`.
        ego2global (np.ndarray): Ego -> global at its LiDAR sweep.
            Shape (4, 4).
        lidar2ego (np.ndarray): LIDAR_TOP -> ego. Shape (4, 4).
        lidar_file (str): File name of its LiDAR sweep (SurroundOcc names
            its label after it).
        cameras (List[CameraView]): Its camera images.
        instances (List[str]): Tokens of the instances annotated in it.
    """
    token: str
    sweep_index: int
    ego2global: np.ndarray
    lidar2ego: np.ndarray
    lidar_file: str
    cameras: List[CameraView] = field(default_factory=list)
    instances: List[str] = field(default_factory=list)


@dataclass
class Track:
    """The boxes of one annotated instance, at the key frames that have it.

    Args:
        token (str): Instance token.
        category (str): nuScenes category name, e.g. ``vehicle.car``.
        sample_tokens (List[str]): The key frames, in time order.
        times (np.ndarray): Their timestamps, seconds. Shape (K,).
        centers (np.ndarray): Box centres, global. Shape (K, 3).
        yaws (np.ndarray): Headings, radians. Shape (K,).
        sizes (np.ndarray): Length, width, height. Shape (K, 3).
    """
    token: str
    category: str
    sample_tokens: List[str]
    times: np.ndarray
    centers: np.ndarray
    yaws: np.ndarray
    sizes: np.ndarray


@dataclass
class SceneSequence:
    """Everything the label generator reads of one scene.

    Args:
        name (str): Scene name (names the Occ3D label folder).
        sweeps (List[Sweep]): All LiDAR sweeps, in time order.
        key_frames (List[KeyFrame]): The samples, in time order.
        tracks (Dict[str, Track]): Annotated instances by token.
        missing (List[str]): Sweep files (not key frames) the tables list
            but the root lacks (a keyframe-only download); left out.
    """
    name: str
    sweeps: List[Sweep]
    key_frames: List[KeyFrame]
    tracks: Dict[str, Track]
    missing: List[str] = field(default_factory=list)


def read_points(path: str) -> np.ndarray:
    """The points of a nuScenes ``.pcd.bin`` (x, y, z, intensity, ring as
    float32), every row as stored (lidarseg labels count them all).

    Args:
        path (str): The file.

    Returns:
        np.ndarray: float32. Shape (P, 5).

    Raises:
        FileNotFoundError: It does not exist.
        ValueError: Its size is not a whole number of points.
    """
    if not osp.isfile(path):
        raise FileNotFoundError(f'LiDAR sweep not found: {path}')
    raw = np.fromfile(path, dtype=np.float32)
    if raw.size % NUM_POINT_FEATS:
        raise ValueError(
            f'LiDAR sweep {path}: {raw.size * 4} bytes is not a whole '
            f'number of points of {NUM_POINT_FEATS} float32 values.')
    return raw.reshape(-1, NUM_POINT_FEATS)


def read_lidarseg(path: str, num_points: int) -> np.ndarray:
    """Raw lidarseg classes (uint8, one per point of the sweep file).

    Args:
        path (str): The ``_lidarseg.bin`` file.
        num_points (int): Points of its sweep file (all rows).

    Returns:
        np.ndarray: uint8 classes 0..31. Shape (num_points,).

    Raises:
        ValueError: If the count differs or a class is out of range.
    """
    labels = np.fromfile(path, dtype=np.uint8)
    if len(labels) != num_points:
        raise ValueError(f'lidarseg {path}: {len(labels)} labels for a '
                         f'sweep of {num_points} points.')
    if labels.size and labels.max() >= len(LIDARSEG_RAW_CLASS_NAMES):
        raise ValueError(f'lidarseg {path}: class {labels.max()} is not a '
                         f'nuScenes-lidarseg class (0..'
                         f'{len(LIDARSEG_RAW_CLASS_NAMES) - 1}).')
    return labels


def _yaw(rotation) -> float:
    from pyquaternion import Quaternion
    return float(Quaternion(rotation).yaw_pitch_roll[0])


def _sensor2global(nusc, sd: dict) -> tuple:
    cs = nusc.get('calibrated_sensor', sd['calibrated_sensor_token'])
    ego = pose_matrix(nusc.get('ego_pose', sd['ego_pose_token']))
    return ego @ pose_matrix(cs), ego, cs


def _lidarseg_path(nusc, root: str, sd_token: str) -> Optional[str]:
    if not hasattr(nusc, 'lidarseg'):
        return None
    try:
        record = nusc.get('lidarseg', sd_token)
    except KeyError:
        return None
    path = osp.join(root, record['filename'])
    return path if osp.isfile(path) else None


def _cameras(nusc, sample: dict) -> List[CameraView]:
    views = []
    for channel, sd_token in sorted(sample['data'].items()):
        sd = nusc.get('sample_data', sd_token)
        if nusc.get('sensor', nusc.get(
                'calibrated_sensor',
                sd['calibrated_sensor_token'])['sensor_token'])[
                    'modality'] != 'camera':
            continue
        cam2global, _, cs = _sensor2global(nusc, sd)
        views.append(CameraView(
            name=channel, cam2global=cam2global,
            intrinsic=np.asarray(cs['camera_intrinsic'], np.float64),
            width=int(sd['width']), height=int(sd['height'])))
    return views


def read_scene(nusc, scene: dict, root: str) -> SceneSequence:
    """Gather one scene (see the module docstring).

    Args:
        nusc (nuscenes.NuScenes): The opened database.
        scene (dict): Its ``scene`` record.
        root (str): Dataset root the file names are relative to.

    Returns:
        SceneSequence: The scene.

    Raises:
        ValueError: If the scene has no sample or its first sample has no
            LIDAR_TOP data.
        FileNotFoundError: If a key frame's LiDAR file is missing (a
            missing sweep between key frames is only left out).
    """
    name = plain_name(scene['name'], 'scene name')
    token = scene['first_sample_token']
    if not token:
        raise ValueError(f'scene {name} has no sample.')
    first = nusc.get('sample', token)
    if 'LIDAR_TOP' not in first['data']:
        raise ValueError(f'scene {name}: sample {token} has no LIDAR_TOP.')
    sd = nusc.get('sample_data', first['data']['LIDAR_TOP'])
    while sd['prev']:
        sd = nusc.get('sample_data', sd['prev'])
    sweeps, key_frames, tracks, missing = [], [], {}, []
    while True:
        path = osp.join(root, sd['filename'])
        if not osp.isfile(path):
            if sd['is_key_frame']:
                raise FileNotFoundError(
                    f'scene {name}: key frame LiDAR file not found: {path}')
            missing.append(path)
            if not sd['next']:
                break
            sd = nusc.get('sample_data', sd['next'])
            continue
        lidar2global, ego2global, cs = _sensor2global(nusc, sd)
        sweeps.append(Sweep(
            token=sd['token'], timestamp=sd['timestamp'] / 1e6,
            path=path, lidar2global=lidar2global,
            ego2global=ego2global,
            lidarseg_path=(_lidarseg_path(nusc, root, sd['token'])
                           if sd['is_key_frame'] else None)))
        if sd['is_key_frame']:
            sample = nusc.get('sample', sd['sample_token'])
            frame = KeyFrame(
                token=plain_name(sample['token'], 'sample token'),
                sweep_index=len(sweeps) - 1, ego2global=ego2global,
                lidar2ego=pose_matrix(cs),
                lidar_file=osp.basename(sd['filename']),
                cameras=_cameras(nusc, sample))
            for ann_token in sample['anns']:
                ann = nusc.get('sample_annotation', ann_token)
                frame.instances.append(ann['instance_token'])
                width, length, height = ann['size']
                tracks.setdefault(ann['instance_token'], []).append(
                    (sample['token'], sd['timestamp'] / 1e6,
                     ann['translation'], _yaw(ann['rotation']),
                     (length, width, height), ann['category_name']))
            key_frames.append(frame)
        if not sd['next']:
            break
        sd = nusc.get('sample_data', sd['next'])
    return SceneSequence(
        name=name, sweeps=sweeps, key_frames=key_frames,
        tracks={tok: _track(tok, rows) for tok, rows in tracks.items()},
        missing=missing)


def _track(token: str, rows: list) -> Track:
    rows = sorted(rows, key=lambda r: r[1])
    return Track(
        token=token, category=rows[0][5],
        sample_tokens=[r[0] for r in rows],
        times=np.array([r[1] for r in rows], np.float64),
        centers=np.array([r[2] for r in rows], np.float64).reshape(-1, 3),
        yaws=np.array([r[3] for r in rows], np.float64),
        sizes=np.array([r[4] for r in rows], np.float64).reshape(-1, 3))
