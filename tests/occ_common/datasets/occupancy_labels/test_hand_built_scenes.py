"""The label generator on scenes whose right answer is worked out by hand.

Both scenes are written by :func:`write_hand_built_scene` (LiDAR 1.8 m
above the ego origin, ego yaw 0, so ego = global up to a shift). Occ3D
voxel ``i`` of an axis covers ``[lo + 0.4 i, lo + 0.4 (i + 1))`` with
``lo = -40, -40, -1``; SurroundOcc's, in the LiDAR frame, ``lo = -50,
-50, -5`` and 0.5 m.
"""
import numpy as np
import pytest

from projects.occ_common.datasets.occupancy_labels import (LabelConfig,
                                                           read_scene,
                                                           scene_labels)
from projects.occ_common.datasets.occupancy_labels.voxelization import EMPTY
from projects.occ_common.testing.hand_built_scene import (
    HandBox, HandSweep, write_hand_built_scene)

#: Returns only (rays without a return are a spinning LiDAR's pattern,
#: which these hand-built points do not follow).
RETURNS_ONLY = dict(no_return_range=0.0)
MANMADE, CAR, OTHERS, FREE = 15, 4, 0, 17


def _frames(root, **settings):
    from nuscenes import NuScenes
    nusc = NuScenes('v1.0-mini', root, verbose=False)
    scene = read_scene(nusc, nusc.scene[0], root)
    return list(scene_labels(scene, LabelConfig(**settings)))


def _occupied(grid):
    return {tuple(v) for v in np.argwhere(grid != EMPTY).tolist()}


def _box(xs, ys, zs):
    return {(x, y, z) for x in xs for y in ys for z in zs}


def _wall(ys):
    """Points of the wall x = 10.2 m at heights 0.25 .. 2.35 m."""
    y, z = np.meshgrid(ys, np.arange(0.25, 2.36, 0.1), indexing='ij')
    return np.stack([np.full(y.size, 10.2), y.ravel(), z.ravel()], axis=1)


@pytest.fixture(scope='module')
def wall_root(tmp_path_factory):
    """Key frame A (ego at the origin) sees the wall's half y < 0 and has
    lidarseg (manmade); sweep B (ego at y = 4) its half y > 0, without
    labels; key frame C (ego at y = 4) has no return at all. A camera
    looks along +x from (1.5, 0.2, 1.5) in the ego frame."""
    left = _wall(np.arange(-1.95, -0.04, 0.1))
    right = _wall(np.arange(0.05, 1.96, 0.1))
    return write_hand_built_scene(str(tmp_path_factory.mktemp('wall')), [
        HandSweep(0.0, (0, 0), left, key=True, raw_class=28),
        HandSweep(0.05, (0, 4), right),
        HandSweep(0.1, (0, 4), np.zeros((0, 3)), key=True, raw_class=28),
    ], camera=True)


def test_static_wall_seen_from_two_poses(wall_root):
    """Each key frame holds the whole wall, both halves, as manmade:
    x = 10.2 is voxel (10.2 + 40) / 0.4 = 125.5 -> 125; y in [-1.95, 1.95]
    -> 95 .. 104 from A, and 85 .. 94 from C (ego y = 4: y - 4 in
    [-5.95, -2.05]); z in [0.25, 2.35] -> 3 .. 8. The half sweep B saw
    takes the class of the nearest labelled return. SurroundOcc (LiDAR
    frame, 0.5 m) at A: x 60.2 / 0.5 -> 120, y 96 .. 103, z - 1.8 in
    [-1.55, 0.55] -> 6 .. 11. Key frame C, without a return of its own,
    still gets the wall: it is accumulated."""
    frame_a, frame_c = _frames(wall_root, **RETURNS_ONLY)
    assert _occupied(frame_a.occ3d) == _box([125], range(95, 105),
                                            range(3, 9))
    assert set(frame_a.occ3d[frame_a.occ3d != EMPTY].tolist()) == {MANMADE}
    assert _occupied(frame_c.occ3d) == _box([125], range(85, 95),
                                            range(3, 9))
    assert _occupied(frame_a.surroundocc) == _box([120], range(96, 104),
                                                  range(6, 12))


def test_voxels_no_ray_reached_are_unobserved(wall_root):
    """A ray from the LiDAR (0, 0, 1.8) to (10.2, -0.05, 1.85) crosses
    (5, -0.025, 1.825): voxel (112, 99, 7), seen. Behind the wall,
    (127, 100, 6) and a voxel no ray goes near, (20, 20, 10), are not in
    mask_lidar. The camera's ray through pixel (31.5, 17.5), direction
    (1, 0.0156, 0.0156) in the ego frame, crosses x = 8 at y 0.30, z 1.60:
    voxel (120, 100, 6), seen; it stops at the wall voxel (125, 100, 6),
    included, so (127, 100, 6) behind it is hidden."""
    frame_a, _ = _frames(wall_root, **RETURNS_ONLY)
    assert frame_a.mask_lidar[112, 99, 7]
    assert not frame_a.mask_lidar[127, 100, 6]
    assert not frame_a.mask_lidar[20, 20, 10]
    assert frame_a.mask_camera[120, 100, 6]
    assert frame_a.mask_camera[125, 100, 6]
    assert not frame_a.mask_camera[127, 100, 6]
    assert frame_a.occ3d[20, 20, 10] == EMPTY


@pytest.fixture(scope='module')
def car_root(tmp_path_factory):
    """A car (4 x 2 x 1.5 m, heading +y) drives past the parked ego at
    x = 8, its centre at y = -10 + 10 t. Sweeps at t = 0, 0.1, 0.2, 0.3
    (key frames: the first and last, where it is annotated) each see one
    metre of its side facing the ego (x = 7): box-frame x in [-1.95,
    -1.05], [-0.95, -0.05], [0.05, 0.95], [1.05, 1.95], heights 0.25 ..
    1.25. No lidarseg: its class comes from its box."""
    sweeps = []
    heights = np.arange(0.25, 1.26, 0.1)
    for k, t in enumerate((0.0, 0.1, 0.2, 0.3)):
        along = np.arange(-1.95 + k, -1.0 + k, 0.1)
        y, z = np.meshgrid(-10 + 10 * t + along, heights, indexing='ij')
        points = np.stack([np.full(y.size, 7.0), y.ravel(), z.ravel()], 1)
        sweeps.append(HandSweep(t, (0, 0), points, key=k in (0, 3)))
    car = HandBox('vehicle.car', (4.0, 2.0, 1.5),
                  centers=[(8, -10, 0.75), (8, -7, 0.75)], yaw=np.pi / 2)
    return write_hand_built_scene(str(tmp_path_factory.mktemp('car')),
                                  sweeps, [car])


def test_car_driving_past_accumulates_in_its_box_frame(car_root):
    """In its box frame the four metres add up to the whole side, placed
    at each key frame's box: at t = 0.3 (y = -7) the side spans y in
    [-8.95, -5.05]: voxels 77 .. 87 (31.05 / 0.4 = 77.6, 34.95 / 0.4 =
    87.4), x 47 / 0.4 = 117.5 -> 117, z 3 .. 5 (1.25 / 0.4, 2.25 / 0.4),
    class car; at t = 0 (y = -10) voxels 70 .. 79. The sweeps between
    the key frames used interpolated boxes (else their metres would be
    missing). Without box frames every metre stays where it was seen:
    at t = 0.3 the first metre, seen at t = 0 at y in [-11.95, -11.05]
    (voxels 70 .. 72), smears behind the car, and the class is unknown
    (others: no lidarseg, no box)."""
    first, last = _frames(car_root, **RETURNS_ONLY)
    assert _occupied(last.occ3d) == _box([117], range(77, 88), range(3, 6))
    assert set(last.occ3d[last.occ3d != EMPTY].tolist()) == {CAR}
    assert _occupied(first.occ3d) == _box([117], range(70, 80), range(3, 6))
    _, smeared = _frames(car_root, box_frame=False, **RETURNS_ONLY)
    assert _box([117], range(70, 73), range(3, 6)) <= _occupied(
        smeared.occ3d)
    assert not _occupied(smeared.occ3d) >= _box([117], range(77, 88),
                                                range(3, 6))
    assert set(smeared.occ3d[smeared.occ3d != EMPTY].tolist()) == {OTHERS}
