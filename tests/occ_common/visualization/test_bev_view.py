"""The top-down view colours each column by its highest drawn voxel."""
import numpy as np
import pytest

from projects.occ_common.visualization import (class_palette, render_bev,
                                               top_labels)

NAMES = ('empty', 'car', 'road')
PALETTE = class_palette(NAMES)
CAR = (255, 158, 0)  # nuScenes challenge colour of 'car'
ROAD = tuple(PALETTE[2])  # fallback colour of label 2
WHITE = (255, 255, 255)


def _grid():
    """8x8x4 grid, 0 = empty, with four hand-placed columns.

    - (2, 5): road at z=0, car at z=3 -> top is car.
    - (6, 1): road at z=1 only -> road.
    - (0, 0): car at z=0 under an ignored (255) voxel at z=3 -> car.
    - (4, 4): road at z=0 and car at z=2, the car voxel outside the mask
      -> road.
    """
    grid = np.zeros((8, 8, 4), dtype=np.int64)
    grid[2, 5, 0], grid[2, 5, 3] = 2, 1
    grid[6, 1, 1] = 2
    grid[0, 0, 0], grid[0, 0, 3] = 1, 255
    grid[4, 4, 0], grid[4, 4, 2] = 2, 1
    mask = np.ones_like(grid, dtype=bool)
    mask[4, 4, 2] = False
    return grid, mask


def test_top_labels_pick_the_highest_drawn_voxel():
    """-1 marks columns with nothing drawn; 62 of the 64 are -1 but 4."""
    grid, mask = _grid()
    drawn = (grid != 0) & (grid != 255) & mask
    top = top_labels(grid, drawn)
    expected = np.full((8, 8), -1)
    expected[2, 5], expected[6, 1], expected[0, 0], expected[4, 4] = 1, 2, 1, 2
    np.testing.assert_array_equal(top, expected)


def test_pixel_colours_follow_the_ego_frame_layout():
    """Column (x, y) lands at row X-1-x, column Y-1-y (x up, y left).

    With scale 2 the block of column (2, 5) is rows 2*(8-1-2) = 10..11 and
    columns 2*(8-1-5) = 4..5.
    """
    grid, mask = _grid()
    image = render_bev(grid, PALETTE, empty_label=0, mask=mask, scale=2)
    assert image.shape == (16, 16, 3) and image.dtype == np.uint8
    for row, col, colour in [(10, 4, CAR), (11, 5, CAR), (2, 12, ROAD),
                             (14, 14, CAR), (6, 6, ROAD)]:
        assert tuple(image[row, col]) == colour, (row, col)
    coloured = (image != 255).any(axis=2).sum()
    assert coloured == 4 * 2 * 2  # four columns of 2x2 pixels
    assert tuple(image[0, 0]) == WHITE


def test_without_mask_the_masked_car_shows():
    """Column (4, 4): car at z=2 is now the top -> CAR at row 3, col 3."""
    grid, _ = _grid()
    image = render_bev(grid, PALETTE, empty_label=0)
    assert tuple(image[3, 3]) == CAR


def test_empty_grid_is_all_background():
    """No drawn voxel: every pixel is the background colour."""
    image = render_bev(
        np.zeros((8, 8, 4), dtype=np.int64), PALETTE, 0, background=(9, 8, 7))
    assert (image == np.array([9, 8, 7], dtype=np.uint8)).all()


def test_out_of_range_label_is_rejected():
    """Label 3 with three classes names the label and the range."""
    grid = np.zeros((8, 8, 4), dtype=np.int64)
    grid[1, 1, 1] = 3
    with pytest.raises(ValueError, match=r'\[3\].*\[0, 3\)'):
        render_bev(grid, PALETTE, 0)
