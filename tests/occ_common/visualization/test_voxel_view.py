"""The painter's-algorithm 3D view: culling, occlusion, colours."""
import numpy as np
import pytest

from projects.occ_common.visualization import class_palette, render_voxels
from projects.occ_common.visualization.voxel_view import look_at, surface_faces

PALETTE = class_palette(('empty', 'car', 'road'))
CAR = (255, 158, 0)
ROAD = tuple(PALETTE[2])
SIZE = (120, 160)  # (H, W)


def test_top_down_view_of_a_solid_block_shows_only_top_faces():
    """From straight above every side face is culled.

    A side face at x = +-4 (centred grid) faces the eye only if
    sign * (eye_x - face_x) > 0; the eye is at x = y = 0, so
    +1 * (0 - 4) < 0 and -1 * (0 + 4) < 0: culled. What is left are top
    faces, whose shade is 1.0: every drawn pixel is exactly ROAD.
    """
    grid = np.full((8, 8, 4), 2, dtype=np.int64)
    image = render_voxels(grid, PALETTE, 0, image_size=SIZE, elevation=90,
                          edge_shade=None)
    drawn = (image != 255).any(axis=2)
    assert drawn.mean() > 0.5
    assert (image[drawn] == np.array(ROAD, dtype=np.uint8)).all()
    assert tuple(image[SIZE[0] // 2, SIZE[1] // 2]) == ROAD


def test_nearer_voxels_cover_farther_ones():
    """A car layer at z=3 over half the grid hides the road at z=0.

    Top-down, y points left (right = forward x x = (0, -1, 0)), so the car
    half y < 4 is the right half of the image. The grid spans about
    0.92 H = 110 px around column 80; the road plane (farther) 0.85 of
    that. Column 80 + 30 lies over y ~ 4 - 30 / 55 * 4 = 1.8 (car) and
    column 80 - 30 over y ~ 4 + 30 / 47 * 4 = 6.6 (road only).
    """
    grid = np.zeros((8, 8, 4), dtype=np.int64)
    grid[:, :, 0] = 2
    grid[:, :4, 3] = 1
    image = render_voxels(grid, PALETTE, 0, image_size=SIZE, elevation=90,
                          edge_shade=None)
    row = SIZE[0] // 2
    assert tuple(image[row, 80 + 30]) == CAR
    assert tuple(image[row, 80 - 30]) == ROAD


def test_surface_faces_are_exposed_and_facing_the_eye():
    """A 2x1x1 bar seen from +x, +y, +z (far away).

    Exposed faces: 2 * 6 - 2 (the shared pair) = 10; facing the eye: the
    +x face of the front voxel, both +y and both +z faces = 5.
    """
    drawn = np.zeros((2, 1, 1), dtype=bool)
    drawn[:] = True
    eye = np.array([50.0, 50.0, 50.0])
    corners, centres, voxels, shade = surface_faces(drawn,
                                                    np.ones(3), eye)
    assert corners.shape == (5, 4, 3)
    assert sorted(shade.tolist()) == [0.7, 0.7, 0.85, 1.0, 1.0]
    assert voxels[shade == 0.85].tolist() == [[1, 0, 0]]


def test_look_at_from_above_keeps_x_up():
    """elevation=90: up = +x, right = forward x x = (0, -1, 0)."""
    eye, axes, distance = look_at(np.array([8.0, 8.0, 4.0]), -150, 90, 40)
    np.testing.assert_allclose(axes[0], [0, -1, 0], atol=1e-9)
    np.testing.assert_allclose(axes[1], [1, 0, 0], atol=1e-9)
    np.testing.assert_allclose(eye, [0, 0, distance], atol=1e-9)


def test_empty_grid_and_anisotropic_voxels():
    """Nothing drawn -> background; 0.5 x 0.5 x 1 m voxels render."""
    empty = render_voxels(np.zeros((8, 8, 4), dtype=np.int64), PALETTE, 0,
                          image_size=SIZE)
    assert empty.shape == SIZE + (3, ) and (empty == 255).all()
    grid = np.zeros((8, 8, 4), dtype=np.int64)
    grid[2:5, 2:5, :2] = 1
    image = render_voxels(grid, PALETTE, 0, voxel_size=(0.5, 0.5, 1.0),
                          image_size=SIZE)
    assert (image != 255).any()


def test_out_of_range_label_is_rejected():
    """Labels outside [0, C) name the label."""
    grid = np.zeros((8, 8, 4), dtype=np.int64)
    grid[0, 0, 0] = 7
    with pytest.raises(ValueError, match=r'\[7\]'):
        render_voxels(grid, PALETTE, 0, image_size=SIZE)
