"""Ahead of the car is up in every top-down picture, in both label frames.

The grids are asymmetric (6 x 4 x 2), so a transposed or mirrored layout
cannot pass: voxel (x=5, y=0) and voxel (x=0, y=3) each land in one corner.
"""
import os.path as osp

import numpy as np
import pytest

from projects.occ_common.fileio.safe_pickle import load_info_file
from projects.occ_common.visualization import (class_palette,
                                               forward_from_lidar2ego,
                                               render_bev, render_voxels,
                                               sample_figure, sample_forward)

NAMES = ('empty', 'car', 'road')
PALETTE = class_palette(NAMES)
CAR = tuple(int(v) for v in PALETTE[1])
ROAD = tuple(int(v) for v in PALETTE[2])
REAL_INFO = osp.join(
    osp.dirname(__file__), '..', '..', '..', '..', 'shared', 'data',
    'nuscenes_real_sample', 'n015-2018-07-24-11-22-45+0800.pkl')


def _rot_z(degrees: float) -> np.ndarray:
    """4x4 rotation about +z."""
    a = np.deg2rad(degrees)
    m = np.eye(4)
    m[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    return m


def _grid() -> np.ndarray:
    """Car at (x=5, y=0), road at (x=0, y=3), both at z=0; 0 = empty."""
    grid = np.zeros((6, 4, 2), dtype=np.int64)
    grid[5, 0, 0] = 1
    grid[0, 3, 0] = 2
    return grid


@pytest.mark.parametrize('degrees, expected', [(0, '+x'), (-90, '+y'),
                                               (90, '-y'), (180, '-x'),
                                               (-88.3, '+y')])
def test_forward_from_lidar2ego(degrees, expected):
    """Ego +x in the working frame is the first row of lidar2ego's
    rotation: for yaw -90 it is (cos -90, -sin -90) = (0, 1), i.e. +y."""
    assert forward_from_lidar2ego(_rot_z(degrees)) == expected


def test_forward_falls_back_to_the_convention_frame():
    """Without lidar2ego: Occ3D's ego frame has +x ahead, SurroundOcc's
    LiDAR frame +y; anything else is drawn as the ego frame."""
    assert sample_forward(None, 'occ3d') == '+x'
    assert sample_forward(None, 'surroundocc') == '+y'
    assert sample_forward(None, None) == '+x'
    assert sample_forward(np.eye(4), 'surroundocc') == '+x'
    with pytest.raises(ValueError, match='forward axis is vertical'):
        forward_from_lidar2ego([[0, 0, 1], [0, 1, 0], [-1, 0, 0]])


def test_ego_frame_grid_puts_x_up():
    """forward '+x': row = X-1-x, column = Y-1-y (left of the car left).

    Car (5, 0): row 0, column 3 (ahead, right). Road (0, 3): row 5,
    column 0 (behind, left). The image is X x Y = 6 x 4.
    """
    image = render_bev(_grid(), PALETTE, empty_label=0, forward='+x')
    assert image.shape == (6, 4, 3)
    assert tuple(image[0, 3]) == CAR
    assert tuple(image[5, 0]) == ROAD


def test_lidar_frame_grid_puts_y_up():
    """forward '+y' (nuScenes LiDAR frame, SurroundOcc): row = Y-1-y,
    column = x, so +x (the car's right) is right.

    Car (5, 0): row 3, column 5 (behind, right). Road (0, 3): row 0,
    column 0 (ahead, left). The image is Y x X = 4 x 6.
    """
    image = render_bev(_grid(), PALETTE, empty_label=0, forward='+y',
                       scale=2)
    assert image.shape == (8, 12, 3)
    assert tuple(image[6, 10]) == CAR and tuple(image[7, 11]) == CAR
    assert tuple(image[0, 0]) == ROAD and tuple(image[1, 1]) == ROAD
    assert (image != 255).any(axis=2).sum() == 2 * 4


@pytest.mark.parametrize('forward, ahead_voxel, right_voxel', [
    ('+x', (5, 2, 0), (2, 0, 0)),
    ('+y', (2, 3, 0), (5, 1, 0)),
])
def test_top_down_3d_view_puts_ahead_up(forward, ahead_voxel, right_voxel):
    """At elevation 90 the 3D view is a top-down picture too: the voxel
    ahead of the car is drawn in the top half, the one on its right in
    the right half."""

    def centre(index):
        grid = np.zeros((6, 4, 2), dtype=np.int64)
        grid[index] = 1
        image = render_voxels(grid, PALETTE, 0, image_size=(60, 60),
                              elevation=90.0, forward=forward,
                              edge_shade=None)
        rows, cols = np.nonzero((image != 255).any(axis=2))
        return rows.mean(), cols.mean()

    row, _ = centre(ahead_voxel)
    assert row < 30, row
    _, col = centre(right_voxel)
    assert col > 30, col


def test_data_sample_picture_takes_forward_from_lidar2ego(monkeypatch):
    """A data sample in nuScenes' LiDAR frame (lidar2ego yaw -90) is drawn
    with +y up; an explicit forward wins."""
    seen = []
    monkeypatch.setattr(sample_figure, 'render_occ_figure',
                        lambda *a, **kw: seen.append(kw['forward']))
    sample = dict(pred_occ=_grid(), lidar2ego=_rot_z(-90))
    sample_figure.render_data_sample(sample, NAMES, 0)
    sample_figure.render_data_sample(
        dict(pred_occ=_grid(), occ_format='occ3d'), NAMES, 0)
    sample_figure.render_data_sample(sample, NAMES, 0, forward='-x')
    assert seen == ['+y', '+x', '-x']


def test_real_lidar_mount_points_y_ahead():
    """The real nuScenes key frame's LIDAR_TOP (yaw about -90 degrees):
    its grid direction ahead of the car is +y."""
    if not osp.isfile(REAL_INFO):
        pytest.skip(f'real nuScenes sample not found at {REAL_INFO} (the '
                    'project checkout has no ../shared)')
    info = load_info_file(REAL_INFO)['data_list'][0]
    lidar2ego = np.asarray(info['lidar_points']['lidar2ego'])
    assert forward_from_lidar2ego(lidar2ego) == '+y'
