"""Tests of RayIoU's rays, casting, counting and origins, by hand."""
import math
import warnings

import numpy as np
import pytest

from projects.occ_common.datasets.nuscenes_classes import OCC3D_CLASS_NAMES
from projects.occ_common.evaluation import (RayHits, cast_rays,
                                            compute_ray_iou, count_ray_hits,
                                            lidar_ray_directions,
                                            ray_iou_from_counts,
                                            scene_ray_origins)
from projects.occ_common.evaluation.ray_casting import lidar_ray_pitches
from projects.occ_common.evaluation.ray_origins import select_origins

FREE = 17
CAR = OCC3D_CLASS_NAMES.index('car')
TRUCK = OCC3D_CLASS_NAMES.index('truck')


def _grid(shape, occupied=()):
    """A free grid with ``{(x, y, z): label}`` set."""
    grid = np.full(shape, FREE, dtype=np.uint8)
    for index, label in dict(occupied).items():
        grid[index] = label
    return grid


def _hits(labels, depths):
    return RayHits(np.asarray(labels), np.asarray(depths, np.float32))


def test_lidar_rays_are_39_beams_of_360_azimuths():
    """Pitches atan(k) - pi/2 for k = 1..10 (the first -pi/4), then the
    last spacing atan(10) - atan(9) ~ 0.0110 rad repeated until >= 0.21:
    (0.21 - (-0.0997)) / 0.0110 ~ 28.2 -> 29 more, 39 in all."""
    pitches = lidar_ray_pitches()
    assert len(pitches) == 39
    assert pitches[0] == pytest.approx(-math.pi / 4)
    assert pitches[9] == pytest.approx(-math.atan(0.1))
    assert pitches[-2] < 0.21 <= pitches[-1]
    rays = lidar_ray_directions()
    assert rays.shape == (39 * 360, 3) and rays.dtype == np.float32
    assert np.allclose(np.linalg.norm(rays, axis=1), 1, atol=1e-6)
    # The second ray: lowest beam, azimuth 1 degree.
    assert np.allclose(rays[1], [
        math.cos(-math.pi / 4) * math.cos(math.radians(1)),
        math.cos(-math.pi / 4) * math.sin(math.radians(1)),
        -math.sin(math.pi / 4)
    ], atol=1e-7)


def test_one_ray_leaves_the_first_occupied_voxel():
    """1 m voxels, origin (0.5, 0.5, 1.5), direction (0.6, 0.8, 0); only
    voxel (2, 3, 1) is a car.

    x crosses 1, 2, 3 at t = 0.83, 2.5, 4.17; y crosses 1, 2, 3, 4 at
    t = 0.625, 1.875, 3.125, 4.375. Merged, the ray enters (2, 3) at
    t = 3.125 (y = 3) and leaves it at t = (3 - 0.5) / 0.6 = 25 / 6 =
    4.1667 m (x = 3): depth 4.1667, label car. The opposite ray meets no
    occupied voxel: free, depth inf.
    """
    grid = _grid((8, 8, 3), {(2, 3, 1): CAR})
    hits, = cast_rays([grid], np.array([[0.5, 0.5, 1.5]]),
                      np.array([[0.6, 0.8, 0.0], [-0.6, -0.8, 0.0]]),
                      pc_range=(0, 0, 0, 8, 8, 3), voxel_size=1.0)
    assert hits.label.tolist() == [CAR, FREE]
    assert hits.depth.dtype == np.float32
    assert hits.depth[0] == pytest.approx(25 / 6, abs=1e-5)
    assert hits.depth[1] == np.inf


def test_tie_at_a_corner_steps_y_before_x():
    """Direction (1, 1, 0) / sqrt(2) from the centre of voxel (0, 0)
    crosses x = 1 and y = 1 at the same t = 0.5 * sqrt(2) = 0.7071 m.
    SparseOcc's kernel then steps y first, so the ray passes through
    (0, 1) (for no length: its exit is also 0.7071 m) but never through
    (1, 0), and next through (1, 1), left at 1.5 * sqrt(2) = 2.1213 m.
    """
    ray = np.array([[1.0, 1.0, 0.0]]) / math.sqrt(2)
    kwargs = dict(pc_range=(0, 0, 0, 4, 4, 1), voxel_size=1.0)
    origin = np.array([[0.5, 0.5, 0.5]])
    via_y, = cast_rays([_grid((4, 4, 1), {(0, 1, 0): CAR})], origin, ray,
                       **kwargs)
    assert via_y.label[0] == CAR
    assert via_y.depth[0] == pytest.approx(0.5 * math.sqrt(2), abs=1e-6)
    via_x, = cast_rays([_grid((4, 4, 1), {(1, 0, 0): CAR,
                                          (1, 1, 0): TRUCK})], origin, ray,
                       **kwargs)
    assert via_x.label[0] == TRUCK
    assert via_x.depth[0] == pytest.approx(1.5 * math.sqrt(2), abs=1e-6)


def test_ray_from_above_the_grid_enters_it():
    """Origin (2.5, 2.5, 6.5) above a 4 m high grid of 1 m voxels; car at
    voxel (2, 2, 1). Down: the ray enters at z = 4 and leaves the car at
    z = 1, 6.5 - 1 = 5.5 m from its origin. Up: it never enters, and
    hits nothing."""
    grid = _grid((4, 4, 4), {(2, 2, 1): CAR})
    hits, = cast_rays([grid], np.array([[2.5, 2.5, 6.5]]),
                      np.array([[0, 0, -1.0], [0, 0, 1.0]]),
                      pc_range=(0, 0, 0, 4, 4, 4), voxel_size=1.0)
    assert hits.label.tolist() == [CAR, FREE]
    assert hits.depth[0] == pytest.approx(5.5)


def test_prediction_one_voxel_further_is_a_hit_at_1m_not_at_0_3m():
    """0.4 m voxels along +x from the centre of voxel 0 (x = 0.2 m): the
    GT car in voxel 5 is left at x = 6 * 0.4 = 2.4 m, depth 2.2 m; the
    predicted car one voxel further, voxel 6, at depth 2.6 m. Error 0.4 m:
    < 1 m -> TP, not < 0.3 m -> no TP. IoU@1 = 1 / (1 + 1 - 1) = 100 %,
    IoU@0.3 = 0 / (1 + 1 - 0) = 0 %."""
    kwargs = dict(pc_range=(0, 0, 0, 4, 1.2, 1.2), voxel_size=0.4)
    origin, ray = np.array([[0.2, 0.6, 0.6]]), np.array([[1.0, 0, 0]])
    gt, pred = (cast_rays([_grid((10, 3, 3), {(x, 1, 1): CAR})], origin,
                          ray, **kwargs)[0] for x in (5, 6))
    assert gt.depth[0] == pytest.approx(2.2, abs=1e-6)
    assert pred.depth[0] == pytest.approx(2.6, abs=1e-6)
    counts = count_ray_hits(pred, gt, thresholds=(1.0, 0.3))
    assert counts['tp'][:, CAR].tolist() == [1, 0]
    assert counts['gt'][CAR] == counts['pred'][CAR] == 1
    metrics = ray_iou_from_counts(counts, thresholds=(1.0, 0.3))
    assert metrics['RayIoU@1/car'] == 100
    assert metrics['RayIoU@0.3/car'] == 0
    assert metrics['RayIoU/car'] == 50


def test_rays_whose_gt_hits_nothing_are_dropped():
    """Ray 0: GT car at 10 m, predicted car at 10.5 m. Ray 1: GT free,
    predicted car (dropped: it counts for neither side). Ray 2: GT car,
    predicted free. car: GT 2, pred 1 (not 2), TP 1 -> 1 / (2 + 1 - 1) =
    50 % (it would be 1 / 3 if ray 1 counted); no other class occurs, so
    RayIoU = 50 %."""
    gt = _hits([CAR, FREE, CAR], [10, np.inf, 5])
    pred = _hits([CAR, CAR, FREE], [10.5, 3, np.inf])
    counts = count_ray_hits(pred, gt)
    assert counts['gt'][CAR] == 2 and counts['pred'][CAR] == 1
    assert counts['tp'][:, CAR].tolist() == [1, 1, 1]
    # Counted for the prediction: the car of ray 0, the free of ray 2.
    assert counts['pred'].sum() == 2 and counts['pred'][FREE] == 1
    metrics = ray_iou_from_counts(counts)
    assert metrics['RayIoU'] == metrics['RayIoU@4'] == 50
    assert math.isnan(metrics['RayIoU/truck'])


def test_counts_are_pooled_over_samples_not_averaged():
    """Sample A: one car ray, right -> car IoU 1 / 1 = 100 %. Sample B:
    three car rays, one right, two predicted truck -> car TP 1, GT 3,
    pred 1: 1 / 3; truck TP 0, GT 0, pred 2: 0 %. The mean of the
    per-sample car IoUs is (100 + 33.3) / 2 = 66.7 %; pooled, car is
    TP 2, GT 4, pred 2: 2 / (4 + 2 - 2) = 50 %, and RayIoU the mean of
    car and truck, (50 + 0) / 2 = 25 %."""
    a = count_ray_hits(_hits([CAR], [5]), _hits([CAR], [5]))
    b = count_ray_hits(_hits([CAR, TRUCK, TRUCK], [5, 6, 7]),
                       _hits([CAR, CAR, CAR], [5, 6, 7]))
    per_sample = [ray_iou_from_counts(c)['RayIoU/car'] for c in (a, b)]
    assert np.mean(per_sample) == pytest.approx(200 / 3)
    pooled = ray_iou_from_counts({k: a[k] + b[k] for k in a})
    assert pooled['RayIoU/car'] == 50
    assert pooled['RayIoU/truck'] == 0
    assert pooled['RayIoU'] == 25


def test_no_rays_gives_nan_without_warnings():
    """An empty set of rays (or of samples) has no defined IoU."""
    empty = _hits(np.zeros(0, np.uint8), [])
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        metrics = ray_iou_from_counts(count_ray_hits(empty, empty))
    assert math.isnan(metrics['RayIoU']) and math.isnan(metrics['RayIoU@1'])


def test_compute_ray_iou_on_occ3d_grids_pools_two_samples():
    """A road (z = 2) with a car block, cast from one origin with all
    14,040 rays. Sample 1 is predicted exactly, sample 2 all free. Every
    class c seen by N_c rays has TP N_c (sample 1), GT 2 N_c, pred N_c:
    IoU = N_c / (2 N_c + N_c - N_c) = 50 %, whatever N_c, so RayIoU and
    each RayIoU@tau are 50 %."""
    gt = np.full((200, 200, 16), FREE, dtype=np.uint8)
    gt[:, :, 2] = OCC3D_CLASS_NAMES.index('driveable_surface')
    gt[110:120, 95:100, 3:6] = CAR
    free = np.full_like(gt, FREE)
    origin = np.array([[0.94, 0.0, 1.84]])
    metrics = compute_ray_iou([gt, free], [gt, gt], [origin, origin])
    for key in ('RayIoU', 'RayIoU@1', 'RayIoU@2', 'RayIoU@4',
                'RayIoU/car', 'RayIoU@1/driveable_surface'):
        assert metrics[key] == pytest.approx(50), key
    assert math.isnan(metrics['RayIoU/bus'])


def test_cast_rays_refuses_bad_grids():
    with pytest.raises(ValueError, match='one shape'):
        cast_rays([_grid((2, 2, 2)), _grid((2, 2, 3))], np.zeros((1, 3)))
    with pytest.raises(ValueError, match='1 to 7 grids'):
        cast_rays([_grid((2, 2, 2))] * 8, np.zeros((1, 3)))


def _pose(x, y, yaw_deg):
    """4x4 rotation about z by ``yaw_deg`` and translation (x, y, 0)."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    return [[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, 0], [0, 0, 0, 1]]


def test_origins_of_a_three_frame_scene():
    """Egos at global (100, 0) yaw 0, (110, 0) yaw 90 and (150, 0) yaw 0
    at t = 0, 1, 2 (listed out of order); every LiDAR at (1, 0, 2) in its
    ego (rotated by -90 degrees, which moves no position): globally at
    (101, 0, 2), (110, 1, 2) and (151, 0, 2).

    - frame 0 (subtract (100, 0)): (1, 0, 2), (10, 1, 2), (51, 0, 2); the
      last has |x| >= 39 and is dropped.
    - frame 1 (subtract (110, 0), rotate by -90: (x, y) -> (y, -x)):
      (-9, 0) -> (0, 9); (0, 1) -> (1, 0); (41, 0) -> (0, -41), dropped.
    - frame 2 (subtract (150, 0)): (-49, 0) and (-40, 1) dropped; (1, 0).
    A frame of another scene changes nothing.
    """
    lidar2ego = np.array(_pose(1, 0, -90))
    lidar2ego[2, 3] = 2
    infos = [
        dict(token=f'f{i}', scene_token='s1', timestamp=t,
             ego2global=_pose(x, 0, yaw),
             lidar_points=dict(lidar2ego=lidar2ego.tolist()))
        for i, t, x, yaw in [(2, 2.0, 150, 0), (0, 0.0, 100, 0),
                             (1, 1.0, 110, 90)]
    ]
    infos.append(dict(token='other', scene_token='s2', timestamp=0.5,
                      ego2global=_pose(101, 0, 0),
                      lidar_points=dict(lidar2ego=lidar2ego.tolist())))
    origins = scene_ray_origins(infos)
    expected = {
        'f0': [[1, 0, 2], [10, 1, 2]],
        'f1': [[0, 9, 2], [1, 0, 2]],
        'f2': [[1, 0, 2]],
        'other': [[1, 0, 2]],
    }
    assert sorted(origins) == sorted(expected)
    for token, value in expected.items():
        assert np.allclose(origins[token], value, atol=1e-5), token


def test_more_than_eight_origins_are_thinned_evenly():
    """20 positions: round(linspace(0, 19, 8)) = round(k * 19 / 7) =
    0, 2.71, 5.43, 8.14, 10.86, 13.57, 16.29, 19 -> 0, 3, 5, 8, 11, 14,
    16, 19."""
    positions = np.stack([np.arange(20.0), np.zeros(20), np.zeros(20)], 1)
    kept = select_origins(positions)
    assert kept[:, 0].tolist() == [0, 3, 5, 8, 11, 14, 16, 19]
