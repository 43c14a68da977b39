"""The real nuScenes key frame beside the checkout (``../shared``).

``../shared/data/nuscenes_real_sample/`` holds one nuScenes key frame with
its mmdet3d v2 info file (six cameras' calibration, the LiDAR sweep). A
user's clone has no ``../shared``: :func:`real_sample_dir` returns None and
the tests that need it skip with :data:`MISSING_REASON`.

The info file is a pickle; it is read with an unpickler that rebuilds
plain containers and numpy scalars only, so the file cannot run code.
"""
import io
import os.path as osp
import pickle
from typing import Optional, Tuple

import numpy as np
import torch
from torch import Tensor

from ..utils.safe_checkpoint import _numpy_reconstruct
from .config_fingerprint import REPO_ROOT

#: Where the sample lies relative to the repository root.
REAL_SAMPLE_DIR = osp.normpath(
    osp.join(REPO_ROOT, '..', 'shared', 'data', 'nuscenes_real_sample'))
INFO_FILE = 'n015-2018-07-24-11-22-45+0800.pkl'
MISSING_REASON = ('the real nuScenes sample ../shared/data/'
                  'nuscenes_real_sample is not beside this checkout')
#: The six cameras in the order of the configs' ``cam_names``.
CAM_NAMES = ('CAM_FRONT', 'CAM_FRONT_RIGHT', 'CAM_FRONT_LEFT', 'CAM_BACK',
             'CAM_BACK_LEFT', 'CAM_BACK_RIGHT')

#: (module, name) pairs the info file may rebuild: numpy scalars and their
#: dtypes, and the byte strings they are stored through.
_ALLOWED = {
    ('numpy', 'dtype'),
    ('numpy.core.multiarray', 'scalar'),
    ('numpy._core.multiarray', 'scalar'),
    ('numpy.core.multiarray', '_reconstruct'),
    ('numpy._core.multiarray', '_reconstruct'),
    ('numpy', 'ndarray'),
    ('_codecs', 'encode'),
}


class _InfoUnpickler(pickle.Unpickler):

    def __init__(self, data: bytes, path: str) -> None:
        super().__init__(io.BytesIO(data))
        self.path = path

    def find_class(self, module: str, name: str):
        if (module, name) not in _ALLOWED:
            raise pickle.UnpicklingError(
                f'{self.path}: refusing to rebuild {module}.{name} (an info '
                'file holds containers and numpy values only)')
        if module.startswith('numpy'):
            # numpy 2 moved core to _core; either name means this numpy's.
            reconstruct, scalar = _numpy_reconstruct()
            return dict(_reconstruct=reconstruct, scalar=scalar).get(
                name) or getattr(np, name)
        return super().find_class(module, name)


def real_sample_dir() -> Optional[str]:
    """The sample's folder, or None when it is not beside the checkout."""
    return REAL_SAMPLE_DIR if osp.isfile(
        osp.join(REAL_SAMPLE_DIR, INFO_FILE)) else None


def load_info(path: Optional[str] = None) -> dict:
    """The sample's info entry (``data_list[0]``), read safely.

    Args:
        path (str, optional): Info file. Defaults to the shared sample's.

    Returns:
        dict: The mmdet3d v2 info of the key frame.
    """
    path = path or osp.join(REAL_SAMPLE_DIR, INFO_FILE)
    with open(path, 'rb') as f:
        infos = _InfoUnpickler(f.read(), path).load()
    return infos['data_list'][0]


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
