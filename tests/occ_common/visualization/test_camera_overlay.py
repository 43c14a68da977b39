"""Voxels projected into the camera images, nearest first."""
import numpy as np
import pytest

from projects.occ_common.synthetic.occ_inputs import ring_camera_rig
from projects.occ_common.visualization import class_palette, overlay_on_cameras

PALETTE = class_palette(('empty', 'car', 'road'))
PC_RANGE = (-8.0, -8.0, -2.0, 8.0, 8.0, 2.0)  # 1 m voxels: 16x16x4 grid


def _rig():
    """Two cameras, 32x64 pixels, focal 32: camera 0 looks along +x."""
    cam2img, lidar2cam = ring_camera_rig(2, (32, 64), 32.0)
    return (cam2img @ lidar2cam).numpy()


def test_voxel_lands_on_its_pixel_and_the_nearest_wins():
    """Two voxels on one ray-ish, the nearer one's colour is kept.

    Voxel (13, 8, 2) has centre (5.5, 0.5, 0.5); camera 0 (right = -y,
    down = -z, forward = +x) sees it at x_c = -0.5, y_c = -0.5, depth 5.5:
    u = 32 * -0.5 / 5.5 + 32 = 29.09, v = 32 * -0.5 / 5.5 + 16 = 13.09,
    pixel (row 13, col 29). Voxel (15, 8, 2), centre (7.5, 0.5, 0.5):
    u = 32 - 16 / 7.5 = 29.87, v = 16 - 2.13 = 13.87: the same pixel,
    farther. Camera 1 looks along -x: both are behind it.
    """
    grid = np.zeros((16, 16, 4), dtype=np.int64)
    grid[13, 8, 2] = 1  # car, near
    grid[15, 8, 2] = 2  # road, far
    images = np.full((2, 32, 64, 3), 50, dtype=np.uint8)
    out = overlay_on_cameras(images, grid, _rig(), PC_RANGE, (1, 1, 1),
                             PALETTE, 0, alpha=1.0, radius=0)
    assert tuple(out[0, 13, 29]) == (255, 158, 0)
    changed = (out != images).any(axis=3)
    assert changed.sum() == 1
    np.testing.assert_array_equal(out[1], images[1])


def test_alpha_blends_and_radius_grows_the_splat():
    """alpha 0.5 over grey 50: (0.5 * 255 + 25, ...) rounded; 3x3 pixels.

    car = (255, 158, 0) -> (152.5, 104, 25) -> rint (152, 104, 25).
    """
    grid = np.zeros((16, 16, 4), dtype=np.int64)
    grid[13, 8, 2] = 1
    images = np.full((2, 32, 64, 3), 50, dtype=np.uint8)
    out = overlay_on_cameras(images, grid, _rig(), PC_RANGE, (1, 1, 1),
                             PALETTE, 0, alpha=0.5, radius=1)
    assert tuple(out[0, 13, 29]) == (152, 104, 25)
    assert (out[0] != 50).any(axis=2).sum() == 9


def test_empty_grid_leaves_the_images_alone():
    """No voxel drawn: the output equals the input."""
    images = np.random.default_rng(0).integers(0, 255, (2, 32, 64, 3),
                                               dtype=np.uint8)
    out = overlay_on_cameras(images, np.zeros((16, 16, 4), dtype=np.int64),
                             _rig(), PC_RANGE, (1, 1, 1), PALETTE, 0)
    np.testing.assert_array_equal(out, images)


def test_geometry_mismatch_is_rejected():
    """Three images with two projections."""
    with pytest.raises(ValueError, match=r'lidar2img of shape \(3, 4, 4\)'):
        overlay_on_cameras(
            np.zeros((3, 32, 64, 3), dtype=np.uint8),
            np.zeros((16, 16, 4), dtype=np.int64), _rig(), PC_RANGE,
            (1, 1, 1), PALETTE, 0)
