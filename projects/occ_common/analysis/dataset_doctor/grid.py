"""The label grid a config trains on: where it lies and what it holds.

The doctor checks the data against what the config believes: the grid's
``point_cloud_range`` and ``voxel_size`` as the config states them (what
the model and ``PointsRangeFilter`` use), the frame and labels of the
dataset's label format (SurroundOcc: LiDAR frame, ``empty`` = 0; Occ3D:
ego frame, ``free`` = 17). :func:`grid_config_check` compares the config
with the label format.
"""
from dataclasses import dataclass
from typing import Tuple

import numpy as np

from ...datasets.occ_formats import IGNORE_INDEX, OCC_FORMATS
from .verdict import CheckResult


@dataclass
class LabelGrid:
    """Geometry and labels of the grid.

    Args:
        occ_format (str): ``'surroundocc'`` or ``'occ3d'``.
        frame (str): ``'lidar'`` or ``'ego'``: the frame of the labels.
        pc_range (np.ndarray): ``(x0, y0, z0, x1, y1, z1)``. Shape (6,).
        voxel_size (np.ndarray): Shape (3,).
        shape (tuple[int, int, int]): Voxels along x, y, z.
        class_names (tuple[str]): Name of every label.
        empty_label (int): Label of empty voxels.
        ignore_index (int): Label of ignored voxels (SurroundOcc's noise,
            which is occupied). Defaults to 255.
    """
    occ_format: str
    frame: str
    pc_range: np.ndarray
    voxel_size: np.ndarray
    shape: Tuple[int, int, int]
    class_names: tuple
    empty_label: int
    ignore_index: int = IGNORE_INDEX

    def lidar2grid(self, lidar2ego: np.ndarray) -> np.ndarray:
        """Key-frame LiDAR frame to the grid's frame. Shape (4, 4)."""
        return np.asarray(lidar2ego, np.float64) if self.frame == 'ego' \
            else np.eye(4)

    def occupied(self, labels: np.ndarray) -> np.ndarray:
        """Occupied voxels: every label but the empty one. Shape (X, Y, Z).
        """
        return labels != self.empty_label


def grid_from_config(cfg, dataset) -> LabelGrid:
    """The grid of a config and its dataset.

    Args:
        cfg (Config): The config (``point_cloud_range``, ``voxel_size``;
            the dataset's metainfo stands in where it has none).
        dataset (NuScenesOccDataset): The split's dataset (label format).

    Returns:
        LabelGrid: The grid.
    """
    spec = OCC_FORMATS[dataset.occ_format]
    meta = dataset.metainfo
    pc_range = np.asarray(
        cfg.get('point_cloud_range', meta['point_cloud_range']), np.float64)
    voxel = np.asarray(cfg.get('voxel_size', meta['voxel_size']), np.float64)
    shape = tuple(int(round(v)) for v in
                  (pc_range[3:] - pc_range[:3]) / voxel)
    return LabelGrid(spec.name, spec.frame, pc_range, voxel, shape,
                     tuple(meta['classes']), spec.empty_label)


def grid_config_check(grid: LabelGrid) -> CheckResult:
    """The config's grid against its label format's.

    A config whose range or voxel size differs from its labels' trains a
    model whose every voxel is somewhere else: the labels of a format are
    written for one grid (:data:`~...datasets.occ_formats.OCC_FORMATS`).

    Args:
        grid (LabelGrid): From :func:`grid_from_config`.

    Returns:
        CheckResult: ``label_grid``; numbers: the largest differences of
        range and voxel size (metres) and of the voxel count per axis.
    """
    spec = OCC_FORMATS[grid.occ_format]
    result = CheckResult('label_grid')
    range_diff = float(np.abs(grid.pc_range - spec.point_cloud_range).max())
    voxel_diff = float(np.abs(grid.voxel_size - spec.voxel_size).max())
    shape_diff = int(np.abs(np.subtract(grid.shape, spec.grid_size)).max())
    result.numbers.update(range_diff_m=range_diff, voxel_diff_m=voxel_diff,
                          shape_diff=shape_diff)
    if range_diff > 1e-6 or voxel_diff > 1e-6:
        result.fail(
            f'the config\'s grid (point_cloud_range '
            f'{grid.pc_range.tolist()}, voxel_size '
            f'{grid.voxel_size.tolist()}) is not the {grid.occ_format} '
            f'labels\' ({list(spec.point_cloud_range)}, '
            f'{list(spec.voxel_size)}): every voxel would be trained at '
            'another place')
    return result
