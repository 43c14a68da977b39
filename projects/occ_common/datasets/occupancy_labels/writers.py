"""Label files in the Occ3D and SurroundOcc layouts.

* Occ3D: ``<out>/gts/<scene name>/<sample token>/labels.npz`` with
  ``semantics`` (uint8, 0 others .. 16, 17 free), ``mask_lidar`` and
  ``mask_camera`` (uint8 0 / 1), as Occ3D-nuScenes ships them.
* SurroundOcc: ``<out>/nuscenes_occ/samples/<LiDAR file name>.npy``, the
  ``(N, 4)`` rows ``x, y, z, label`` of the occupied voxels (label 0 is
  SurroundOcc's ``noise``, ignored by its loaders), as SurroundOcc ships
  them.

``tools/create_data.py --occ3d-root <out>/gts --surroundocc-root
<out>/nuscenes_occ`` links them into the info files. Names come from the
tables and are checked to be plain tokens (:func:`.sequence.plain_name`)
before they become paths. Each file is written to a temporary name and
renamed, so an interrupted run never leaves a truncated label behind.
"""
import os
import os.path as osp

import numpy as np

from ..nuscenes_classes import OCC3D_FREE_LABEL
from .sequence import plain_name
from .voxelization import EMPTY

#: Sub-folders of the output root, as ``tools/create_data.py`` expects.
OCC3D_DIR, SURROUNDOCC_DIR = 'gts', 'nuscenes_occ'


def occ3d_path(out_dir: str, scene: str, token: str) -> str:
    """Where a key frame's Occ3D label goes."""
    return osp.join(out_dir, OCC3D_DIR, plain_name(scene, 'scene name'),
                    plain_name(token, 'sample token'), 'labels.npz')


def surroundocc_path(out_dir: str, lidar_file: str) -> str:
    """Where a key frame's SurroundOcc label goes (named after its LiDAR
    file, e.g. ``n015-...__LIDAR_TOP__1532402927647951.pcd.bin.npy``)."""
    name = plain_name(lidar_file, 'LiDAR file name')
    return osp.join(out_dir, SURROUNDOCC_DIR, 'samples', f'{name}.npy')


def _replace(path: str, write) -> str:
    os.makedirs(osp.dirname(path), exist_ok=True)
    partial = path + '.partial'
    with open(partial, 'wb') as f:
        write(f)
    os.replace(partial, path)
    return path


def write_occ3d(path: str, labels: np.ndarray, mask_lidar: np.ndarray,
                mask_camera: np.ndarray) -> str:
    """Write an Occ3D ``labels.npz``.

    Args:
        path (str): Target file.
        labels (np.ndarray): uint8 classes 0..16, :data:`.EMPTY` where
            empty. Shape (200, 200, 16).
        mask_lidar (np.ndarray): bool. Shape (200, 200, 16).
        mask_camera (np.ndarray): bool. Shape (200, 200, 16).

    Returns:
        str: ``path``.
    """
    semantics = np.where(labels == EMPTY, OCC3D_FREE_LABEL,
                         labels).astype(np.uint8)
    return _replace(path, lambda f: np.savez_compressed(
        f, semantics=semantics, mask_lidar=mask_lidar.astype(np.uint8),
        mask_camera=mask_camera.astype(np.uint8)))


def surroundocc_rows(labels: np.ndarray) -> np.ndarray:
    """SurroundOcc's sparse rows of a label grid.

    Args:
        labels (np.ndarray): uint8 classes 0..16, :data:`.EMPTY` where
            empty. Shape (X, Y, Z).

    Returns:
        np.ndarray: int32 ``x, y, z, label`` of the occupied voxels,
        sorted by index. Shape (N, 4).
    """
    index = np.argwhere(labels != EMPTY)
    return np.concatenate([index, labels[tuple(index.T)][:, None]],
                          axis=1).astype(np.int32)


def write_surroundocc(path: str, labels: np.ndarray) -> str:
    """Write a SurroundOcc ``.npy`` (see :func:`surroundocc_rows`).

    Returns:
        str: ``path``.
    """
    rows = surroundocc_rows(labels)
    return _replace(path, lambda f: np.save(f, rows))
