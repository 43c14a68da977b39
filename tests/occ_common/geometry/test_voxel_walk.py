"""The voxel walk's pass counts and grid helpers."""
import numpy as np

from projects.occ_common.geometry.voxel_walk import (OccGrid, pass_counts,
                                                     traverse)

GRID = OccGrid((0.0, 0.0, 0.0), 1.0, (4, 4, 4))


def test_pass_counts_leave_out_the_end_voxel():
    """A ray from (0.5, 1.5, 1.5) along +x for 2.0 m ends at x = 2.5: it
    walks voxels x = 0, 1, 2 of row (y=1, z=1) and ends in x = 2, so it
    passes through x = 0 and 1 only. A second ray, 10 m from x = -3,
    enters at x = 0 and leaves the grid after x = 3 without ending in it:
    it passes through all four. No rays: no counts."""
    origins = np.array([[0.5, 1.5, 1.5], [-3.0, 1.5, 1.5]])
    dirs = np.array([[1.0, 0, 0], [1.0, 0, 0]])
    counts = pass_counts(GRID, origins, dirs, np.array([2.0, 10.0]))
    assert counts[:, 1, 1].tolist() == [2, 2, 1, 1]
    assert counts.sum() == 6
    visited = traverse(GRID, origins, dirs, np.array([2.0, 10.0]))
    assert visited[:, 1, 1].all() and visited.sum() == 4
    assert not pass_counts(GRID, np.zeros(3), np.zeros((0, 3)),
                           np.zeros(0)).any()


def test_voxel_index_keeps_the_points_inside():
    """(0.5, 3.99, 0) is voxel (0, 3, 0); (4.0, 0, 0) lies on the upper
    face, outside [0, 4); (-0.01, 1, 1) is outside below."""
    ijk, inside = GRID.voxel_index(np.array([[0.5, 3.99, 0.0],
                                             [4.0, 0.0, 0.0],
                                             [-0.01, 1.0, 1.0]]))
    assert ijk.tolist() == [[0, 3, 0]] and inside.tolist() == [True, False,
                                                               False]
    assert GRID.flat_index(ijk).tolist() == [12]
