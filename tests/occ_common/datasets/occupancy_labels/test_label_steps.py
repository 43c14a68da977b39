"""The label generator's steps, each on inputs worked out by hand."""
import numpy as np
import pytest

from projects.occ_common.datasets.occupancy_labels.accumulation import \
    SweepRays
from projects.occ_common.datasets.occupancy_labels.box_frame import (
    assign_to_boxes, track_poses)
from projects.occ_common.datasets.occupancy_labels.densification import (
    fill_ground, fill_hull, object_hull)
from projects.occ_common.datasets.occupancy_labels.free_space import (
    carve, ray_passes)
from projects.occ_common.datasets.occupancy_labels.no_return import (
    firing_pattern, missing_directions, ring_elevations)
from projects.occ_common.datasets.occupancy_labels.semantics import (
    category_label, static_labels, vote)
from projects.occ_common.datasets.occupancy_labels.sequence import (Track,
                                                                    plain_name)
from projects.occ_common.datasets.occupancy_labels.voxelization import EMPTY
from projects.occ_common.geometry.voxel_walk import OccGrid


def _track(times, centers, yaws):
    return Track('t', 'vehicle.car', ['s'] * len(times),
                 np.asarray(times, float), np.asarray(centers, float),
                 np.asarray(yaws, float), np.ones((len(times), 3)))


def test_track_poses_interpolate_and_extrapolate():
    """Boxes at t = 0 (origin, yaw 0) and t = 1 ((2, 0, 0), yaw pi/2):
    t = 0.5 is halfway, (1, 0, 0) and pi/4; t = 1.25 continues the last
    interval's motion, (2.5, 0, 0) and 1.25 pi/2; t = -0.5 the first's,
    (-1, 0, 0) and -pi/4; t = 1.6 is beyond the 0.5 s window: no box.
    Yaws 3.0 and -3.0 are 0.283 rad apart across pi: halfway is pi, not
    0. One annotation is held still within the window."""
    track = _track([0, 1], [[0, 0, 0], [2, 0, 0]], [0, np.pi / 2])
    centers, yaws, valid = track_poses(track, np.array([0.5, 1.25, -0.5,
                                                        1.6]), 0.5)
    assert centers[:3, 0] == pytest.approx([1.0, 2.5, -1.0])
    assert yaws[:3] == pytest.approx([np.pi / 4, 0.625 * np.pi,
                                      -np.pi / 4])
    assert valid.tolist() == [True, True, True, False]
    across = _track([0, 1], [[0, 0, 0]] * 2, [3.0, -3.0])
    assert abs(track_poses(across, np.array([0.5]), 0.5)[1][0]) == \
        pytest.approx(np.pi)
    still = _track([2], [[5, 5, 1]], [0.3])
    centers, yaws, valid = track_poses(still, np.array([1.4, 2.3]), 0.5)
    assert centers.tolist() == [[5, 5, 1]] * 2 and valid.tolist() == [
        False, True]


def test_points_are_assigned_to_grown_boxes():
    """A 4 x 2 x 2 m box at (0, 0, 1) heading +y: (0, 1.9, 1) is 1.9 m
    along it, inside; (1.1, 0, 1) is 1.1 m to its right, inside the 0.2 m
    margin (box-frame (0, -1.1, 0)); (1.3, 0, 1) is outside. (0, 0, 0.05)
    is 0.05 m above the bottom: under a 0.1 m clearance it stays with the
    ground, a lowered bottom (-0.2) takes it. Of two overlapping boxes the
    nearer centre wins."""
    points = np.array([[0, 1.9, 1], [1.1, 0, 1], [1.3, 0, 1],
                       [0, 0, 0.05]], float)
    box = (np.array([[0, 0, 1.0]]), np.array([np.pi / 2]),
           np.array([[4.0, 2, 2]]), 0.2)
    owner, local = assign_to_boxes(points, *box, np.full(4, 0.1))
    assert owner.tolist() == [0, 0, -1, -1]
    assert local[0] == pytest.approx([1.9, 0, 0])
    assert local[1] == pytest.approx([0, -1.1, 0])
    owner, _ = assign_to_boxes(points, *box, np.full(4, -0.2))
    assert owner.tolist() == [0, 0, -1, 0]
    two = assign_to_boxes(np.array([[0.9, 0, 1.0]]),
                          np.array([[0, 0, 1.0], [1.5, 0, 1.0]]),
                          np.zeros(2), np.full((2, 3), 2.0), 0.2,
                          np.zeros(1))[0]
    assert two.tolist() == [1]


def test_missing_rays_from_the_ring_pattern():
    """Rings 0 and 2 fire at 8 azimuths 0.1 + k pi/4 (elevations -0.1 and
    0.1 rad); ring 0 returned nothing at k = 3, ring 1 never returned.
    The step is the median gap, pi/4; the phase 0.1; ring 1's elevation
    is interpolated to 0. Missing: ring 0 at azimuth 0.1 + 3 pi/4, and
    all 8 of ring 1, level."""
    rows = []
    for ring, elevation, steps in ((0, -0.1, [0, 1, 2, 4, 5, 6, 7]),
                                   (2, 0.1, range(8))):
        for k in steps:
            a = 0.1 + k * np.pi / 4
            rows.append([10 * np.cos(elevation) * np.cos(a),
                         10 * np.cos(elevation) * np.sin(a),
                         10 * np.sin(elevation), 0, ring])
    pattern = firing_pattern(np.array(rows))
    assert pattern.phase == pytest.approx(0.1)
    elevations = ring_elevations([pattern])
    assert elevations == pytest.approx([-0.1, 0.0, 0.1])
    dirs = missing_directions(pattern, elevations)
    assert len(dirs) == 9
    a = 0.1 + 3 * np.pi / 4
    assert dirs[0] == pytest.approx([np.cos(-0.1) * np.cos(a),
                                     np.cos(-0.1) * np.sin(a),
                                     np.sin(-0.1)])
    assert dirs[1:, 2] == pytest.approx(np.zeros(8))
    assert firing_pattern(np.array([[1.0, 0, 0, 0, 0]])) is None


def test_carving_removes_a_return_in_open_air():
    """20 rays from (0.5, 0.5, 0.5) along +x end on a wall in voxel
    x = 5 (1 m voxels): 20 returns there, no pass. A spurious return at
    x = 2.5 is one return where the 20 rays passed: 1 / 21 < 0.1, carved.
    A point outside the grid is kept."""
    grid = OccGrid((0.0, 0.0, 0.0), 1.0, (8, 2, 2))
    wall = np.tile([5.5, 0.5, 0.5], (20, 1))
    noise = np.array([[2.5, 0.5, 0.5]])
    rays = [SweepRays(origin=np.array([0.5, 0.5, 0.5]),
                      ends=np.concatenate([wall, noise]))]
    passes = ray_passes(grid, rays)
    assert passes[:, 0, 0].tolist() == [21, 21, 20, 20, 20, 0, 0, 0]
    points = np.concatenate([wall[:1], noise, [[20.0, 0.5, 0.5]]])
    hits_passes = np.concatenate([wall, points])
    keep = carve(grid, hits_passes, passes, 0.1)
    assert keep[-3:].tolist() == [True, False, True]


def test_static_labels_copy_the_nearest_labelled_return():
    """Labelled: manmade (raw 28 -> 15) at the origin, driveable (raw 24
    -> 11) at x = 10. Unlabelled returns at x = 1 and 9 copy them; within
    0.5 m there is none to copy: others (0). Without any label: others."""
    points = np.array([[0, 0, 0], [10, 0, 0], [1, 0, 0], [9, 0, 0]], float)
    raw = np.array([28, 24, -1, -1])
    assert static_labels(points, raw, np.inf).tolist() == [15, 11, 15, 11]
    assert static_labels(points, raw, 0.5).tolist() == [15, 11, 0, 0]
    assert static_labels(points, np.full(4, -1), np.inf).tolist() == [0] * 4
    assert category_label('vehicle.car') == 4
    assert category_label('a.new.category') == 0


def test_vote_takes_the_majority_and_the_higher_class_at_a_tie():
    """Voxel 5 has classes 3, 3, 4: 3. Voxel 7 has 1 and 2: a tie, 2.
    No point: no voxel."""
    voxels, classes = vote(np.array([5, 7, 5, 7, 5]),
                           np.array([3, 1, 3, 2, 4], np.uint8))
    assert voxels.tolist() == [5, 7] and classes.tolist() == [3, 2]
    assert len(vote(np.zeros(0, int), np.zeros(0, np.uint8))[0]) == 0


def test_fill_ground_from_the_nearest_observed_column():
    """Five columns of 1 m: column 0 has driveable ground (11) at layer 1;
    column 2 a tree crown at layer 3 (above layer 1 + 1: filled); column
    4 a car from layer 2 (not above: kept). Unlimited radius fills
    columns 1, 2, 3 at layer 1; 1.5 m only column 1; 0 nothing."""
    def grid():
        labels = np.full((5, 1, 4), EMPTY, np.uint8)
        labels[0, 0, 1], labels[2, 0, 3], labels[4, 0, 2] = 11, 16, 4
        return labels
    filled = fill_ground(grid(), 1.0, np.inf)
    assert filled[:, 0, 1].tolist() == [11, 11, 11, 11, EMPTY]
    assert filled[2, 0, 3] == 16 and filled[4, 0, 2] == 4
    assert fill_ground(grid(), 1.0, 1.5)[:, 0, 1].tolist() == [
        11, 11, EMPTY, EMPTY, EMPTY]
    assert (fill_ground(grid(), 1.0, 0.0) == grid()).all()


def test_object_hull_fills_the_voxels_inside():
    """The corners of the cube [-1, 1]^3 in 0.5 m voxels from -2: the
    centres -0.75 .. 0.75 (4 per axis) are inside: 64 voxels, one of them
    already another object's and kept. Turned by 45 degrees the centre
    (0.75, 0.75, 0.25) lies 1.06 m along the box's x: outside; (0.75,
    0.25, 0.25) at (0.71, -0.35): inside. Points on a plane span no
    volume: no hull."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1)
                        for z in (-1, 1)], float)
    hull = object_hull(corners)
    grid = OccGrid((-2.0, -2.0, -2.0), 0.5, (8, 8, 8))
    labels = np.full(grid.shape, EMPTY, np.uint8)
    labels[2, 2, 2] = 9
    fill_hull(labels, grid, np.eye(4), hull, np.zeros(3), 0.0, np.ones(3), 4)
    assert (labels == 4).sum() == 63 and labels[2, 2, 2] == 9
    assert (labels[2:6, 2:6, 2:6] != EMPTY).all()
    turned = np.full(grid.shape, EMPTY, np.uint8)
    fill_hull(turned, grid, np.eye(4), hull, np.zeros(3), np.pi / 4,
              np.ones(3), 4)
    assert turned[5, 5, 4] == EMPTY and turned[5, 4, 4] == 4
    assert object_hull(corners[corners[:, 2] > 0]) is None
    assert object_hull(corners[:3]) is None


@pytest.mark.parametrize('bad', ['', '../gts', 'a/b', '.hidden', 'a b'])
def test_plain_names_only(bad):
    """Names from the tables become paths: only plain ones pass."""
    with pytest.raises(ValueError, match='cannot name an output file'):
        plain_name(bad, 'scene name')
    assert plain_name('n015-2018+0800__LIDAR_TOP__1.pcd.bin', 'x')
