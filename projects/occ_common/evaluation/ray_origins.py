"""Ray origins of RayIoU: where the virtual LiDARs of a sample stand.

SparseOcc (Liu et al., ECCV 2024; its ``EgoPoseDataset``) casts the rays
of a sample not only from the sample's own LiDAR but from the LiDAR of
every key frame of the same scene, past and future, expressed in the
sample's ego frame, so that surfaces hidden from the current position are
scored as well. Positions whose x or y lies 39 m or more from the ego are
dropped (the grid ends at 40 m); of more than 8 left, the 8 at
``round(linspace(0, n - 1, 8))`` in time order are kept.

The info files of this library (:mod:`..datasets.info_format`) hold what
this needs for every key frame: ``token``, ``timestamp``, ``scene_token``
(and ``scene_name``), ``ego2global`` and ``lidar_points.lidar2ego``.
"""
import os.path as osp
from collections import defaultdict
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..datasets.info_format import check_info_file
from ..fileio.safe_pickle import load_info_file

#: Origins kept per sample at most.
MAX_RAY_ORIGINS = 8
#: An origin is kept if |x| and |y| in the sample's ego frame are below
#: this many metres.
RAY_ORIGIN_RANGE = 39.0


def _scene_of(entry: dict) -> str:
    """The scene an info entry belongs to (token, else name)."""
    scene = entry.get('scene_token') or entry.get('scene_name')
    if scene is None:
        raise ValueError(f'ray origins: sample {entry.get("token")} has '
                         'neither scene_token nor scene_name.')
    return scene


def _lidar2ego(entry: dict) -> np.ndarray:
    """``lidar_points.lidar2ego`` of a raw entry (or the top-level
    ``lidar2ego`` of one parsed by the dataset). Shape (4, 4)."""
    lidar = entry.get('lidar_points') or {}
    matrix = lidar.get('lidar2ego', entry.get('lidar2ego'))
    if matrix is None:
        raise ValueError(f'ray origins: sample {entry.get("token")} has no '
                         'lidar_points.lidar2ego.')
    return np.asarray(matrix, dtype=np.float64).reshape(4, 4)


def select_origins(positions: np.ndarray,
                   max_origins: int = MAX_RAY_ORIGINS,
                   max_xy: float = RAY_ORIGIN_RANGE) -> np.ndarray:
    """Keep the positions near the ego and thin them out evenly.

    Args:
        positions (np.ndarray): LiDAR positions in the sample's ego frame,
            in time order. Shape (F, 3).
        max_origins (int): At most this many are kept. Defaults to 8.
        max_xy (float): Bound on |x| and |y|, metres. Defaults to 39.

    Returns:
        np.ndarray: The kept positions, in time order. Shape (T, 3).
    """
    near = (np.abs(positions[:, 0]) < max_xy) & \
        (np.abs(positions[:, 1]) < max_xy)
    kept = positions[near]
    if len(kept) > max_origins:
        # np.round, as SparseOcc (halves go to the even index).
        pick = np.round(np.linspace(0, len(kept) - 1, max_origins))
        kept = kept[pick.astype(np.int64)]
    return kept


def scene_ray_origins(data_list: Sequence[dict],
                      max_origins: int = MAX_RAY_ORIGINS,
                      max_xy: float = RAY_ORIGIN_RANGE
                      ) -> Dict[str, np.ndarray]:
    """Ray origins of every sample of an info file's ``data_list``.

    The frames of a scene are the entries sharing its ``scene_token`` (or
    ``scene_name``), ordered by ``timestamp``; a scene split over several
    files (or thinned by ``load_interval``) therefore sees fewer origins,
    so pass the whole split.

    Args:
        data_list (Sequence[dict]): Info entries with ``token``,
            ``timestamp``, ``scene_token`` / ``scene_name``, ``ego2global``
            (4, 4) and ``lidar_points.lidar2ego`` (4, 4).
        max_origins (int): At most this many per sample. Defaults to 8.
        max_xy (float): Bound on |x| and |y|, metres. Defaults to 39.

    Returns:
        dict[str, np.ndarray]: Sample token to its origins in its ego
        frame, float64. Shape (T, 3) each, 1 <= T <= ``max_origins``.
    """
    scenes: Dict[str, List[dict]] = defaultdict(list)
    for entry in data_list:
        scenes[_scene_of(entry)].append(entry)
    origins = {}
    for frames in scenes.values():
        frames = sorted(frames, key=lambda e: e['timestamp'])
        lidar2ego = np.stack([_lidar2ego(e) for e in frames])
        lidar2global = np.stack([
            np.asarray(e['ego2global'], dtype=np.float64).reshape(4, 4)
            for e in frames
        ]) @ lidar2ego
        # Homogeneous LiDAR positions in the global frame. Shape (4, F).
        lidar_at = lidar2global[:, :, 3].T
        for i, entry in enumerate(frames):
            # Through the sample's LiDAR frame, rounded to float32 there,
            # as SparseOcc does (about 1e-6 m, but it decides ties).
            in_lidar = (np.linalg.inv(lidar2global[i]) @ lidar_at)[:3]
            in_lidar = in_lidar.T.astype(np.float32).astype(np.float64)
            in_lidar[i] = 0.0
            positions = in_lidar @ lidar2ego[i, :3, :3].T + \
                lidar2ego[i, :3, 3]
            origins[entry['token']] = select_origins(positions, max_origins,
                                                     max_xy)
    return origins


def info_path(ann_file: str, data_root: Optional[str] = None) -> str:
    """``ann_file`` below ``data_root`` unless it is absolute."""
    if data_root and not osp.isabs(ann_file):
        return osp.join(data_root, ann_file)
    return ann_file


def load_origin_frames(ann_file: str,
                       data_root: Optional[str] = None
                       ) -> Tuple[Dict[str, np.ndarray], Dict[str, tuple]]:
    """:func:`scene_ray_origins` of an info file, and each sample's frame.

    Args:
        ann_file (str): Info file written by ``tools/create_data.py``,
            relative to ``data_root`` or absolute.
        data_root (str, optional): Folder ``ann_file`` is relative to.
            Defaults to None.

    Returns:
        tuple[dict, dict]: Sample token to origins (Shape (T, 3) each),
        and sample token to ``(timestamp, ego2global)`` (Shape (4, 4)),
        by which a sample of the evaluated dataset is matched with the
        entry its origins come from.
    """
    path = info_path(ann_file, data_root)
    if not osp.isfile(path):
        raise FileNotFoundError(f'ray origins: info file not found: {path}')
    infos = load_info_file(path)
    check_info_file(infos, path)
    frames = {
        entry['token']: (entry['timestamp'],
                         np.asarray(entry['ego2global'],
                                    np.float64).reshape(4, 4))
        for entry in infos['data_list']
    }
    return scene_ray_origins(infos['data_list']), frames


def load_ray_origins(ann_file: str,
                     data_root: Optional[str] = None
                     ) -> Dict[str, np.ndarray]:
    """The origins of :func:`load_origin_frames` alone: sample token to
    origins, Shape (T, 3) each."""
    return load_origin_frames(ann_file, data_root)[0]
