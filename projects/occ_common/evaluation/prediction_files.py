"""Reading back the prediction files of ``tools/test.py --format-only``.

The reader of :mod:`.occupancy_export`'s two layouts: an Occ3D
``<sample token>.npz`` (the grid under ``semantics`` / ``arr_0`` /
``pred``) and a SurroundOcc ``<LiDAR file name>.npy`` of (N, 4) rows ``x,
y, z, label`` of the occupied voxels. Nothing pickled is loaded.
"""
import os.path as osp
from typing import Mapping, Sequence

import numpy as np

from .occupancy_export import OCC3D_PRED_KEYS, safe_file_name


def prediction_path(folder: str, convention: str,
                    sample: Mapping) -> str:
    """Where ``tools/test.py --format-only`` wrote a sample's prediction.

    Args:
        folder (str): The ``--format-only`` folder.
        convention (str): ``'occ3d'`` or ``'surroundocc'``.
        sample (Mapping): The sample's metainfo (``token`` for Occ3D,
            ``lidar_path`` for SurroundOcc).

    Returns:
        str: The file's path (it may not exist).

    Raises:
        ValueError: If the sample lacks the key that names its file, or
            the convention is unknown.
    """
    if convention not in ('occ3d', 'surroundocc'):
        raise ValueError(f"Expected convention 'occ3d' or 'surroundocc', "
                         f'got {convention!r}.')
    key = 'token' if convention == 'occ3d' else 'lidar_path'
    if not sample.get(key):
        raise ValueError(f'sample {sample.get("sample_idx", "?")} has no '
                         f'{key!r} to find its {convention} prediction file.')
    if convention == 'occ3d':
        return osp.join(folder, safe_file_name(sample[key], 'sample token') +
                        '.npz')
    name = safe_file_name(osp.basename(sample[key]), 'file name')
    return osp.join(folder, name + '.npy')


def read_prediction(path: str, grid_shape: Sequence[int],
                    empty_label: int) -> np.ndarray:
    """A prediction file as a dense label grid.

    Args:
        path (str): An Occ3D ``.npz`` or SurroundOcc ``.npy`` file.
        grid_shape (Sequence[int]): ``(X, Y, Z)`` of the grid.
        empty_label (int): Label of the voxels a SurroundOcc file does not
            list.

    Returns:
        np.ndarray: Shape (X, Y, Z), uint8.

    Raises:
        FileNotFoundError: If ``path`` does not exist.
        ValueError: If it holds no grid of ``grid_shape`` or an index
            outside it (naming the file).
    """
    if not osp.isfile(path):
        raise FileNotFoundError(f'prediction file not found: {path}')
    shape = tuple(int(v) for v in grid_shape)
    if path.endswith('.npz'):
        with np.load(path, allow_pickle=False) as data:
            keys = [k for k in OCC3D_PRED_KEYS if k in data.files]
            if not keys:
                raise ValueError(f'{path}: expected one of '
                                 f'{list(OCC3D_PRED_KEYS)}, found '
                                 f'{data.files}.')
            grid = np.asarray(data[keys[0]])
        if grid.shape != shape:
            raise ValueError(f'{path}: grid of shape {grid.shape}, expected '
                             f'{shape}.')
        return grid.astype(np.uint8)
    rows = np.load(path, allow_pickle=False)
    if rows.ndim != 2 or rows.shape[1] != 4:
        raise ValueError(f'{path}: expected (N, 4) rows x, y, z, label, '
                         f'got shape {rows.shape}.')
    rows = rows.astype(np.int64)
    outside = (rows[:, :3] < 0).any(1) | (rows[:, :3] >= shape).any(1)
    if outside.any():
        raise ValueError(f'{path}: voxel {rows[outside][0, :3].tolist()} is '
                         f'outside the grid {shape}.')
    grid = np.full(shape, empty_label, dtype=np.uint8)
    grid[rows[:, 0], rows[:, 1], rows[:, 2]] = rows[:, 3]
    return grid
