"""Geometry and classes of the two occupancy label formats.

* SurroundOcc (Wei et al., ICCV 2023): 200 x 200 x 16 voxels of 0.5 m in
  the LiDAR frame, x, y in [-50, 50] m, z in [-5, 3] m; files are the
  occupied voxels as (N, 4) integer rows ``x, y, z, label`` with label 0 =
  noise, 1..16 the classes; voxels not listed are empty.
* Occ3D-nuScenes (Tian et al., NeurIPS 2023): 200 x 200 x 16 voxels of
  0.4 m in the ego frame, x, y in [-40, 40] m, z in [-1, 5.4] m;
  ``labels.npz`` holds ``semantics`` (0 others, 1..16 classes, 17 free),
  ``mask_lidar`` and ``mask_camera``.

In the dense grids this library works with, SurroundOcc's noise becomes the
ignore value 255 and its empty voxels label 0, so its class list is
``('empty', 16 classes)``; Occ3D keeps its own 18 labels.
"""
from typing import NamedTuple, Tuple

from .nuscenes_classes import OCC3D_CLASS_NAMES, OCC_CLASS_NAMES

#: Label of voxels (and points, pixels) excluded from losses and metrics.
IGNORE_INDEX = 255

#: SurroundOcc's 17 dense labels: ``empty`` (0), then the 16 classes.
SURROUNDOCC_CLASS_NAMES = ('empty', ) + tuple(OCC_CLASS_NAMES)


class OccFormat(NamedTuple):
    """The fixed geometry and label space of one occupancy format.

    Attributes:
        name (str): ``'surroundocc'`` or ``'occ3d'``.
        frame (str): Frame of the grid, ``'lidar'`` or ``'ego'``.
        point_cloud_range (tuple[float]): x_min, y_min, z_min, x_max, y_max,
            z_max in metres.
        voxel_size (tuple[float]): Edge lengths in metres.
        grid_size (tuple[int]): Voxels along x, y, z.
        class_names (tuple[str]): Name of every label value.
        empty_label (int): Label of unoccupied voxels.
    """

    name: str
    frame: str
    point_cloud_range: Tuple[float, ...]
    voxel_size: Tuple[float, ...]
    grid_size: Tuple[int, ...]
    class_names: Tuple[str, ...]
    empty_label: int


OCC_FORMATS = dict(
    surroundocc=OccFormat('surroundocc', 'lidar',
                          (-50.0, -50.0, -5.0, 50.0, 50.0, 3.0),
                          (0.5, 0.5, 0.5), (200, 200, 16),
                          SURROUNDOCC_CLASS_NAMES, 0),
    occ3d=OccFormat('occ3d', 'ego', (-40.0, -40.0, -1.0, 40.0, 40.0, 5.4),
                    (0.4, 0.4, 0.4), (200, 200, 16),
                    tuple(OCC3D_CLASS_NAMES), 17))
