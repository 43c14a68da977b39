"""The real nuScenes key frame beside the checkout (``../shared``).

``../shared/data/nuscenes_real_sample/`` holds one nuScenes key frame with
its mmdet3d v2 info file (six cameras' calibration, the LiDAR sweep). A
user's clone has no ``../shared``: :func:`real_sample_dir` returns None and
the tests that need it skip with :data:`MISSING_REASON`.

The info file is a pickle; it is read with the library's restricted
unpickler (:func:`~projects.occ_common.fileio.load_info_file`), so it
cannot run code.
"""
import os.path as osp
from typing import Optional, Tuple

import numpy as np
import torch
from torch import Tensor

from ..fileio.safe_pickle import load_info_file
from .tool_runs import REPO_ROOT

#: Where the sample lies relative to the repository root.
REAL_SAMPLE_DIR = osp.normpath(
    osp.join(REPO_ROOT, '..', 'shared', 'data', 'nuscenes_real_sample'))
INFO_FILE = 'n015-2018-07-24-11-22-45+0800.pkl'
MISSING_REASON = ('the real nuScenes sample ../shared/data/'
                  'nuscenes_real_sample is not beside this checkout')
#: The six cameras in the order of the configs' ``cam_names``.
CAM_NAMES = ('CAM_FRONT', 'CAM_FRONT_RIGHT', 'CAM_FRONT_LEFT', 'CAM_BACK',
             'CAM_BACK_LEFT', 'CAM_BACK_RIGHT')


def real_sample_dir() -> Optional[str]:
    """The sample's folder, or None when it is not beside the checkout."""
    return REAL_SAMPLE_DIR if osp.isfile(
        osp.join(REAL_SAMPLE_DIR, INFO_FILE)) else None


def real_info_file() -> Optional[str]:
    """The sample's info file, or None when it is not beside the
    checkout."""
    folder = real_sample_dir()
    return None if folder is None else osp.join(folder, INFO_FILE)


def load_info(path: Optional[str] = None) -> dict:
    """The sample's info entry (``data_list[0]``), read safely.

    Args:
        path (str, optional): Info file. Defaults to the shared sample's.

    Returns:
        dict: The mmdet3d v2 info of the key frame.
    """
    path = path or osp.join(REAL_SAMPLE_DIR, INFO_FILE)
    return load_info_file(path)['data_list'][0]


def real_cameras(info: Optional[dict] = None) -> Tuple[Tensor, Tensor]:
    """Intrinsics and extrinsics of the six cameras.

    Args:
        info (dict, optional): From :func:`load_info`. Defaults to the
            shared sample's.

    Returns:
        tuple[Tensor, Tensor]: ``cam2img`` (the 3x3 intrinsics padded to
        4x4) and ``lidar2cam``, float64, each Shape (6, 4, 4), in
        :data:`CAM_NAMES` order.
    """
    info = load_info() if info is None else info
    cam2img = torch.eye(4, dtype=torch.float64).repeat(len(CAM_NAMES), 1, 1)
    lidar2cam = []
    for k, cam in enumerate(CAM_NAMES):
        images = info['images'][cam]
        cam2img[k, :3, :3] = torch.as_tensor(np.asarray(images['cam2img']))
        lidar2cam.append(torch.as_tensor(np.asarray(images['lidar2cam'])))
    return cam2img, torch.stack(lidar2cam)


def real_lidar2img(info: Optional[dict] = None) -> Tensor:
    """``cam2img @ lidar2cam`` of the six cameras (no augmentation).

    Args:
        info (dict, optional): From :func:`load_info`. Defaults to the
            shared sample's.

    Returns:
        Tensor: float64. Shape (6, 4, 4), in :data:`CAM_NAMES` order.
    """
    cam2img, lidar2cam = real_cameras(info)
    return cam2img @ lidar2cam
