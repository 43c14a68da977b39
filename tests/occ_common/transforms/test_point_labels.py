"""Point labels from the occupancy grid (the fallback without lidarseg)."""
import numpy as np

from projects.occ_common.transforms.point_labels import occupancy_point_labels

#: A 2 x 2 x 1 grid of 1 m voxels over x, y in [0, 2), z in [0, 1):
#: (0, 0) car (4), (1, 0) empty / others (0), (0, 1) free (17), (1, 1)
#: hidden by the camera mask (255).
GRID = np.array([[[4], [17]], [[0], [255]]], np.uint8)
RANGE = np.array([0.0, 0.0, 0.0, 2.0, 2.0, 1.0])
SIZE = np.array([1.0, 1.0, 1.0])


def test_each_point_takes_its_voxel_label():
    """(0.5, 0.5, 0.5) in voxel (0, 0): 4. (0.999, 0, 0) still (0, 0): 4.
    (1.0, 0.2, 0.2): the lower bound belongs to voxel (1, 0): empty -> 255.
    (0.2, 1.5, 0.5) in (0, 1): free -> 255. (1.5, 1.5, 0.5) in (1, 1):
    hidden (255) -> 255. (-0.1, 0.5, 0.5), (0.5, 0.5, 1.0), (2.0, 0, 0):
    outside the grid -> 255."""
    xyz = np.array([[0.5, 0.5, 0.5], [0.999, 0, 0], [1.0, 0.2, 0.2],
                    [0.2, 1.5, 0.5], [1.5, 1.5, 0.5], [-0.1, 0.5, 0.5],
                    [0.5, 0.5, 1.0], [2.0, 0, 0]])
    labels = occupancy_point_labels(xyz, GRID, RANGE, SIZE)
    np.testing.assert_array_equal(labels, [4, 4] + [255] * 6)
    assert labels.dtype == np.int64


def test_every_class_passes_and_ignore_index_is_used():
    """All 18 values of an Occ3D grid: 1..16 pass, 0 and 17 become the
    given ignore index (here 99); no point gives an empty array."""
    grid = np.arange(18, dtype=np.uint8).reshape(18, 1, 1)
    xyz = np.stack([np.arange(18) + 0.5, np.full(18, 0.5),
                    np.full(18, 0.5)], 1)
    labels = occupancy_point_labels(
        xyz, grid, [0, 0, 0, 18, 1, 1], SIZE, ignore_index=99)
    np.testing.assert_array_equal(labels, [99] + list(range(1, 17)) + [99])
    assert occupancy_point_labels(np.zeros((0, 3)), GRID, RANGE,
                                  SIZE).shape == (0, )
