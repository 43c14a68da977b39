"""Labels against LiDAR on hand-made grids, and the config's grid.

The grid: 8 x 8 x 4 voxels of 1 m over [0, 8] x [0, 8] x [0, 4] in the
LiDAR frame (the sensor at the origin), a wall of label 4 (``car``)
filling x in {4, 5}, y in {2..5}, z in {0..3}; 64 points on its face at
x = 4.2 (y and z on an 8 x 8 lattice, 0.5 m apart from 2.25 / 0.25).
"""
from types import SimpleNamespace

import numpy as np
import pytest

from projects.occ_common.analysis.dataset_doctor.grid import (
    LabelGrid, grid_config_check, grid_from_config)
from projects.occ_common.analysis.dataset_doctor.labels_lidar import (
    check_labels_vs_lidar, surface_voxels)
from projects.occ_common.analysis.dataset_doctor.sample_data import SampleData
from projects.occ_common.analysis.dataset_doctor.verdict import (FAIL, PASS,
                                                                 SKIP, WARN)
from projects.occ_common.datasets.occ_formats import SURROUNDOCC_CLASS_NAMES

GRID = LabelGrid('surroundocc', 'lidar', np.array([0., 0, 0, 8, 8, 4]),
                 np.ones(3), (8, 8, 4), SURROUNDOCC_CLASS_NAMES, 0)


def _wall(shift_x: int = 0) -> np.ndarray:
    labels = np.zeros(GRID.shape, np.uint8)
    labels[4 + shift_x:6 + shift_x, 2:6, :] = 4
    return labels


def _sample(labels, points=None, lidarseg=None) -> SampleData:
    if points is None:
        y, z = np.meshgrid(2.25 + 0.5 * np.arange(8),
                           0.25 + 0.5 * np.arange(8), indexing='ij')
        points = np.stack([np.full(64, 4.2), y.ravel(), z.ravel(),
                           np.zeros(64)], axis=1).astype(np.float32)
    return SampleData(index=0, token='t', info={}, points=points,
                      lidar2ego=np.eye(4), ego2global=np.eye(4),
                      labels=labels, lidarseg=lidarseg)


def test_surface_voxels_of_a_cube():
    """A 3^3 cube in a 5^3 grid: every voxel but its centre borders free
    space (26); a full grid has no surface (outside the grid is unknown,
    not free); an empty one neither."""
    occupied = np.zeros((5, 5, 5), bool)
    occupied[1:4, 1:4, 1:4] = True
    surface = surface_voxels(occupied)
    assert surface.sum() == 26 and not surface[2, 2, 2]
    assert surface_voxels(np.ones((5, 5, 5), bool)).sum() == 0
    assert surface_voxels(np.zeros((5, 5, 5), bool)).sum() == 0


def test_points_on_the_labels_pass():
    """All 64 points lie in the wall's face voxels (x = 4): hit 1.0; the
    elevated ones (z above the 10th height percentile 0.25 + 1 m: 48 of
    them) too; lidarseg 'car' (4) on every point: same class 1.0."""
    result = check_labels_vs_lidar(
        _sample(_wall(), lidarseg=np.full(64, 4)), GRID)
    assert result.verdict == PASS, result.findings
    assert result.numbers['hit'] == 1.0
    assert result.numbers['hit_elevated'] == 1.0
    assert result.numbers['points_in_grid'] == 64
    assert result.numbers['same_class'] == 1.0
    assert result.numbers['car.hit'] == 1.0
    assert result.numbers['best_other.gain'] <= 0


def test_a_shifted_grid_fails_and_names_the_shift():
    """The wall written two voxels further along x: no point (nor the
    point 0.5 m further along its ray, still in voxel 4) lies on it as
    configured (hit 0), all of them read with a (2, 0, 0) shift."""
    result = check_labels_vs_lidar(_sample(_wall(shift_x=2)), GRID)
    assert result.verdict == FAIL
    assert result.numbers['hit'] == 0.0
    assert result.numbers['best_other.hit'] == 1.0
    assert result.numbers['best_other.gain'] == 1.0
    assert 'shifted by (2, 0, 0) voxels' in result.findings[0][1]


def test_too_few_points_and_no_labels():
    """No point: a warning (nothing to judge by); no labels: skipped."""
    empty = check_labels_vs_lidar(
        _sample(_wall(), points=np.zeros((0, 4), np.float32)), GRID)
    assert empty.verdict == WARN
    assert empty.numbers['points_in_grid'] == 0
    assert check_labels_vs_lidar(_sample(None), GRID).verdict == SKIP


def test_config_grid_against_the_label_format():
    """SurroundOcc's own grid passes (differences 0); a config with 0.4 m
    voxels over [-40, 40] m (Occ3D's) fails: range 10 m off, voxel 0.1 m,
    and 200 voxels per axis either way."""
    dataset = SimpleNamespace(
        occ_format='surroundocc',
        metainfo=dict(point_cloud_range=[-50, -50, -5, 50, 50, 3],
                      voxel_size=[0.5] * 3, classes=SURROUNDOCC_CLASS_NAMES))
    own = grid_config_check(grid_from_config({}, dataset))
    assert own.verdict == PASS
    assert own.numbers == dict(range_diff_m=0.0, voxel_diff_m=0.0,
                               shape_diff=0)
    other = grid_config_check(grid_from_config(
        dict(point_cloud_range=[-40, -40, -5, 40, 40, 3],
             voxel_size=[0.4, 0.4, 0.5]), dataset))
    assert other.verdict == FAIL
    assert other.numbers['range_diff_m'] == 10.0
    assert other.numbers['voxel_diff_m'] == pytest.approx(0.1)
    assert other.numbers['shape_diff'] == 0
