"""Prediction files for the benchmarks' servers and tools (format-only).

Two layouts, one per label convention (a prediction is written in the
frame and label space it was made in; the frames differ, so one is never
converted into the other):

* Occ3D (CVPR 2023 occupancy challenge): one ``<sample_token>.npz`` per
  key frame holding the uint8 labels (0 others .. 17 free), Shape
  (200, 200, 16), compressed. The challenge's own example writes the grid
  as the archive's only, unnamed array (``arr_0``), its ``labels.npz``
  call it ``semantics``, and SparseOcc's RayIoU script (``ray_metrics.py
  --pred-dir``) reads ``pred``; each file holds all three names, so a
  reader of any finds it (a mostly free grid compresses to a few kB, so
  the copies cost little). The server takes one ``.zip`` of the folder,
  written beside it.
* SurroundOcc: one ``<LiDAR file name>.npy`` per key frame in the layout of
  SurroundOcc's own label files, the (N, 4) rows ``x, y, z, label`` of the
  occupied voxels (uint8 while indices fit: 200 x 200 x 16), so every reader
  of
  those labels (``LoadOccupancyGT``, ``tools/misc/visualize_occ.py``) reads a
  prediction as it reads a label.

On the synthetic world an Occ3D file is ~10 kB and a SurroundOcc file
~290 kB (73k occupied voxels; ``.npy`` is uncompressed, as SurroundOcc's
labels are), against 11.5 MB that mmengine's ``DumpResults`` pickles for the
prediction, GT and masks of a sample alone (int64 and bool grids), 17 MB
with the depth and 2-D label maps of the six cameras.
"""
import os
import os.path as osp
import zipfile
from typing import Iterable

import numpy as np

from ..fileio.safe_names import safe_file_name

#: Keys of the grid in an Occ3D prediction file (see the module docstring).
OCC3D_PRED_KEYS = ('semantics', 'arr_0', 'pred')


def _uint8_grid(pred, name: str) -> np.ndarray:
    """A 3-D label grid as uint8, refusing values that do not fit."""
    array = pred.detach().cpu().numpy() if hasattr(pred, 'detach') \
        else np.asarray(pred)
    if array.ndim != 3 or not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f'{name}: expected an integer label grid of shape '
                         f'(X, Y, Z), got {array.dtype} {array.shape}.')
    if array.size and (array.min() < 0 or array.max() > 255):
        raise ValueError(f'{name}: labels {array.min()}..{array.max()} do '
                         'not fit in uint8.')
    return array.astype(np.uint8)


def write_occ3d_prediction(folder: str, sample_token: str, pred) -> str:
    """Write ``<folder>/<sample_token>.npz`` (see the module docstring).

    Args:
        folder (str): Output folder, created if needed.
        sample_token (str): nuScenes sample token.
        pred (np.ndarray | Tensor): Labels 0..17, Shape (X, Y, Z).

    Returns:
        str: The written file.
    """
    token = safe_file_name(sample_token, 'sample token')
    grid = _uint8_grid(pred, f'prediction of sample {token}')
    os.makedirs(folder, exist_ok=True)
    path = osp.join(folder, f'{token}.npz')
    np.savez_compressed(path, **{key: grid for key in OCC3D_PRED_KEYS})
    return path


def write_surroundocc_prediction(folder: str, name: str, pred,
                                 empty_label: int = 0) -> str:
    """Write ``<folder>/<name>.npy``: SurroundOcc label rows of ``pred``.

    Args:
        folder (str): Output folder, created if needed.
        name (str): File stem, e.g. the key frame's LiDAR file name
            (``n015-...__LIDAR_TOP__1532402927647951.pcd.bin``), as
            SurroundOcc names its labels.
        pred (np.ndarray | Tensor): Labels 0 (empty) .. 16, Shape
            (X, Y, Z).
        empty_label (int): Label not listed. Defaults to 0.

    Returns:
        str: The written file.
    """
    stem = safe_file_name(name, 'file name')
    grid = _uint8_grid(pred, f'prediction {stem}')
    occupied = np.argwhere(grid != empty_label)
    rows = np.concatenate(
        [occupied, grid[tuple(occupied.T)][:, None]], axis=1)
    dtype = np.uint8 if max(grid.shape) <= 256 else np.uint16
    os.makedirs(folder, exist_ok=True)
    path = osp.join(folder, f'{stem}.npy')
    np.save(path, rows.astype(dtype))
    return path


def write_prediction(folder: str, convention: str, sample: dict, pred,
                     empty_label: int) -> str:
    """Write one sample's prediction in its convention's layout.

    Args:
        folder (str): Output folder.
        convention (str): ``'occ3d'`` (named by the sample's ``token``) or
            ``'surroundocc'`` (named by its ``lidar_path``'s file name).
        sample (dict): The data sample (``token`` / ``lidar_path``).
        pred (np.ndarray | Tensor): Shape (X, Y, Z).
        empty_label (int): Label of empty space.

    Returns:
        str: The written file's name (inside ``folder``).

    Raises:
        ValueError: If the sample lacks the key that names its file.
    """
    key = 'token' if convention == 'occ3d' else 'lidar_path'
    if not sample.get(key):
        raise ValueError(
            f'sample {sample.get("sample_idx", "?")} has no {key!r} to name '
            f'its {convention} prediction file; PackOccInputs packs it.')
    if convention == 'occ3d':
        path = write_occ3d_prediction(folder, sample[key], pred)
    else:
        path = write_surroundocc_prediction(
            folder, osp.basename(sample[key]), pred, empty_label)
    return osp.basename(path)


def zip_folder_files(folder: str, names: Iterable[str]) -> str:
    """Zip ``names`` of ``folder`` into ``<folder>.zip`` under the folder's
    name (``zip -r folder.zip folder`` of those files), as the Occ3D server
    takes it. The ``.npz`` files are compressed already, so they are
    stored.

    Returns:
        str: The zip file.
    """
    folder = osp.normpath(folder)
    target = folder + '.zip'
    base = osp.basename(folder)
    with zipfile.ZipFile(target, 'w', zipfile.ZIP_STORED) as archive:
        for name in sorted(names):
            archive.write(osp.join(folder, name), osp.join(base, name))
    return target
