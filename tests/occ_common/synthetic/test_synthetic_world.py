"""Tests of the synthetic nuScenes-format world generator.

One tiny world (1 scene, 2 key frames, 160x90 images, 80 azimuth steps) is
generated once per session and checked through nuscenes-devkit and
pyquaternion, which share no code with the generator: the devkit loads
it, the LiDAR, camera and occupancy data agree with each other and with
the world's geometry.
"""
import dataclasses
import glob
import hashlib
import json
import os
import os.path as osp
import runpy

import cv2
import numpy as np
import pytest
from nuscenes.eval.lidarseg.utils import LidarsegClassMapper
from nuscenes.nuscenes import NuScenes
from pyquaternion import Quaternion
from shapely.geometry import Polygon

from projects.occ_common.datasets.nuscenes_classes import (
    LIDARSEG_RAW_CLASS_NAMES, LIDARSEG_RAW_TO_OCC16, OCC3D_CLASS_NAMES,
    OCC3D_FREE_LABEL, OCC_CLASS_NAMES, lidarseg_to_occ16)
from projects.occ_common.synthetic import (CAMERA_NAMES, META_PATH, OCC3D_GRID,
                                           SURROUNDOCC_GRID, camera_label_path,
                                           generate_synthetic_nuscenes,
                                           load_world)
from projects.occ_common.synthetic.camera import (Camera, box_pixel_candidates,
                                                  make_camera_rig,
                                                  render_camera)
from projects.occ_common.synthetic.layout import build_world
from projects.occ_common.synthetic.lidar import (LIDAR_ELEVATIONS_DEG,
                                                 beam_directions,
                                                 make_lidar2ego, scan_lidar)
from projects.occ_common.synthetic.occupancy import (RAW_FREE, traverse,
                                                     voxelize)
from projects.occ_common.synthetic.raycast import (TARGET_GROUND, TARGET_NONE,
                                                   cast_rays, cone_candidates)
from projects.occ_common.synthetic.world import Boxes
from projects.occ_common.testing.tiny_world import make_tiny_world

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.dirname(
    osp.abspath(__file__)))))


@pytest.fixture(scope='module')
def tiny_root(tmp_path_factory):
    return make_tiny_world(str(tmp_path_factory.mktemp('tiny_world')))


@pytest.fixture(scope='module')
def nusc(tiny_root):
    return NuScenes(version='v1.0-mini', dataroot=tiny_root, verbose=False)


@pytest.fixture(scope='module')
def world(tiny_root):
    return load_world(tiny_root, 'scene-0001')


def _sensor2global(nusc, sd_token):
    """Sensor -> global of a sample_data, from the devkit's records."""
    sd = nusc.get('sample_data', sd_token)
    cs = nusc.get('calibrated_sensor', sd['calibrated_sensor_token'])
    pose = nusc.get('ego_pose', sd['ego_pose_token'])

    def matrix(record):
        transform = np.eye(4)
        transform[:3, :3] = Quaternion(record['rotation']).rotation_matrix
        transform[:3, 3] = record['translation']
        return transform

    return matrix(pose) @ matrix(cs), matrix(cs), sd


def _load_points(root, sd):
    points = np.fromfile(osp.join(root, sd['filename']), dtype=np.float32)
    return points.reshape(-1, 5)


def _apply(transform, points):
    return points @ transform[:3, :3].T + transform[:3, 3]


def _box_surface_distance(world, points, t):
    """|signed distance| of points to the nearest box surface, at time t.
    Shape (N,)."""
    boxes = world.boxes
    delta = points[:, None, :2] - boxes.centers_at(t)[None, :, :2]
    c, s = np.cos(boxes.yaw), np.sin(boxes.yaw)
    local = np.stack([c * delta[..., 0] + s * delta[..., 1],
                      -s * delta[..., 0] + c * delta[..., 1],
                      points[:, None, 2] - boxes.centers_at(t)[None, :, 2]],
                     axis=-1)
    excess = np.abs(local) - boxes.size[None] / 2
    outside = np.linalg.norm(np.maximum(excess, 0), axis=-1)
    inside = np.minimum(excess.max(axis=-1), 0)
    return np.abs(outside + inside).min(axis=1)


def test_class_tables_match_the_official_mapping(nusc):
    """The raw -> 16-class table equals nuscenes-devkit's lidarseg challenge
    mapping, e.g. raw 17 vehicle.car -> 4, raw 24 driveable -> 11, raw 30
    vegetation -> 16, raw 0 noise -> 0, raw 19 ambulance -> 0 (ignored)."""
    mapper = LidarsegClassMapper(nusc)
    official = mapper.fine_idx_2_coarse_idx_mapping
    assert [official[i] for i in range(32)] == LIDARSEG_RAW_TO_OCC16.tolist()
    assert [LIDARSEG_RAW_TO_OCC16[i] for i in (17, 24, 30, 0, 19)] == [
        4, 11, 16, 0, 0]
    assert LIDARSEG_RAW_TO_OCC16.dtype == np.uint8
    assert not LIDARSEG_RAW_TO_OCC16.flags.writeable
    names = {c['index']: c['name'] for c in nusc.category}
    assert [names[i] for i in range(32)] == list(LIDARSEG_RAW_CLASS_NAMES)
    assert len(OCC_CLASS_NAMES) == 16 and OCC_CLASS_NAMES[3] == 'car'
    assert OCC3D_CLASS_NAMES[0] == 'others'
    assert OCC3D_CLASS_NAMES[OCC3D_FREE_LABEL] == 'free'


def test_lidarseg_to_occ16_checks_its_input():
    """Maps per the table; an empty array stays empty; floats and values
    outside 0..31 raise and name the source."""
    labels = lidarseg_to_occ16(np.array([17, 2, 28], dtype=np.uint8))
    assert labels.tolist() == [4, 7, 15]
    assert lidarseg_to_occ16(np.zeros(0, np.uint8)).shape == (0, )
    with pytest.raises(ValueError, match='x.bin.*dtype float32'):
        lidarseg_to_occ16(np.zeros(3, np.float32), 'x.bin')
    with pytest.raises(ValueError, match=r'0\.\.31 in y.bin.*32\.\.32'):
        lidarseg_to_occ16(np.array([32]), 'y.bin')


def test_cast_rays_by_hand():
    """Box centred at (0, 0, 0.5), length 4, width 2, height 1, heading +y
    (yaw pi / 2), so it spans x in [-1, 1], y in [-2, 2], z in [0, 1]:

    * from (-5, 0, 0.5) along +x: enters the x = -1 face at t = -1 - (-5)
      = 4 (t = 3 if the yaw were ignored), normal -x;
    * from (0, 0, 2) down: hits the top z = 1 at t = 1, before the ground
      at t = 2, normal +z;
    * from (5, 5, 2) down: hits the ground at t = 2;
    * from (5, 5, 2) along +y: hits nothing.

    Two of the four rays cross the box ignoring occlusion. No rays and no
    boxes are fine too."""
    origins = [(-5, 0, 0.5), (0, 0, 2), (5, 5, 2), (5, 5, 2)]
    dirs = [(1.0, 0, 0), (0, 0, -1.0), (0, 0, -1.0), (0, 1.0, 0)]
    box = dict(centers=np.array([[0, 0, 0.5]]), sizes=np.array([[4.0, 2, 1]]),
               yaws=np.array([np.pi / 2]))
    hits = [cast_rays(np.array(o, float), np.array([d]), **box)
            for o, d in zip(origins, dirs)]
    assert hits[0].t[0] == pytest.approx(4.0) and hits[0].target[0] == 0
    assert hits[0].normal[0] == pytest.approx([-1, 0, 0])
    assert hits[1].t[0] == pytest.approx(1.0) and hits[1].target[0] == 0
    assert hits[1].normal[0] == pytest.approx([0, 0, 1])
    assert hits[2].t[0] == pytest.approx(2.0)
    assert hits[2].target[0] == TARGET_GROUND
    assert hits[3].target[0] == TARGET_NONE and np.isinf(hits[3].t[0])
    assert sum(int(h.box_ray_counts[0]) for h in hits) == 2
    empty = cast_rays(np.ones(3), np.zeros((0, 3)), np.zeros((0, 3)),
                      np.zeros((0, 3)), np.zeros(0))
    assert empty.t.shape == (0, ) and empty.box_ray_counts.shape == (0, )


def test_traverse_by_hand():
    """Grid of 4x4x4 voxels of 1 m from (0, 0, 0). A ray from (0.5, 1.5,
    1.5) along +x for 2.0 m ends at x = 2.5: it visits voxels x = 0, 1, 2
    of row (y=1, z=1). With voxel (1, 1, 1) occupied it stops there,
    inclusive: x = 0, 1. A ray starting outside at x = -3 enters at x = 0
    and, 10 m long, runs out of the grid after x = 3. No rays: nothing."""
    grid = type(OCC3D_GRID)((0.0, 0.0, 0.0), 1.0, (4, 4, 4))
    direction = np.array([[1.0, 0, 0]])
    visited = traverse(grid, np.array([0.5, 1.5, 1.5]), direction,
                       np.array([2.0]))
    assert np.argwhere(visited).tolist() == [[0, 1, 1], [1, 1, 1], [2, 1, 1]]
    occupied = np.zeros((4, 4, 4), bool)
    occupied[1, 1, 1] = True
    visited = traverse(grid, np.array([0.5, 1.5, 1.5]), direction,
                       np.array([2.0]), occupied)
    assert np.argwhere(visited).tolist() == [[0, 1, 1], [1, 1, 1]]
    visited = traverse(grid, np.array([-3.0, 1.5, 1.5]), direction,
                       np.array([10.0]))
    assert np.argwhere(visited)[:, 0].tolist() == [0, 1, 2, 3]
    assert not traverse(grid, np.zeros(3), np.zeros((0, 3)),
                        np.zeros(0)).any()


def test_camera_rig_and_pixel_convention():
    """The rig looks where nuScenes' does: optical axes (camera +z in the
    ego frame) at yaws 0, -55, 55, 180, 110, -110 deg within the 0.6 deg of
    mount tilt; CAM_FRONT's focal length is 1266.4 px at 1600x900. Pixel
    (u, v) covers [u, u + 1): with K = [[10, 0, 5], [0, 10, 5], [0, 0, 1]]
    pixel (0, 0)'s ray goes through (0.5, 0.5), i.e. ((0.5 - 5) / 10,
    (0.5 - 5) / 10, 1) = (-0.45, -0.45, 1), and pixel (9, 9)'s through
    (0.45, 0.45, 1)."""
    rig = make_camera_rig((1600, 900))
    assert [c.name for c in rig] == list(CAMERA_NAMES)
    for camera, yaw in zip(rig, (0, -55, 55, 180, 110, -110)):
        axis = camera.cam2ego[:3, 2]
        error = (np.degrees(np.arctan2(axis[1], axis[0])) - yaw + 180) % 360
        assert abs(error - 180) < 0.6
        assert abs(axis[2]) < 0.01
    assert rig[0].intrinsic[0, 0] == pytest.approx(1266.4)
    small = Camera('CAM_TEST', np.array([[10.0, 0, 5], [0, 10, 5], [0, 0, 1]]),
                   np.eye(4), 10, 10)
    rays = small.pixel_rays()
    assert rays.shape == (100, 3)
    assert rays[0] == pytest.approx([-0.45, -0.45, 1.0])
    assert rays[99] == pytest.approx([0.45, 0.45, 1.0])


def test_culling_matches_brute_force():
    """Testing each box only against the pixels of its clipped projection
    (cameras) or the beams / azimuth columns of its bounding cylinder
    (LiDAR) gives exactly the hits of testing every ray against every
    box."""
    world = build_world(np.random.default_rng(5), 1.0, False, False)
    boxes, t = world.boxes, 0.5
    corners = boxes.corners_at(t)
    ego_pose = world.ego_pose(t)
    shape = dict(centers=boxes.centers_at(t), sizes=boxes.size,
                 yaws=boxes.yaw, t_min=0.1)
    for camera in make_camera_rig((64, 36)):
        cam2world = ego_pose @ camera.cam2ego
        dirs = camera.pixel_rays() @ cam2world[:3, :3].T
        culled = cast_rays(cam2world[:3, 3], dirs, candidates=(
            box_pixel_candidates(camera, cam2world, corners)), **shape)
        brute = cast_rays(cam2world[:3, 3], dirs, **shape)
        assert np.array_equal(culled.target, brute.target)
        assert np.array_equal(culled.box_ray_counts, brute.box_ray_counts)
    lidar2world = ego_pose @ make_lidar2ego()
    elevations = np.deg2rad(LIDAR_ELEVATIONS_DEG)
    dirs = beam_directions(64, 0.01) @ lidar2world[:3, :3].T
    yaw = np.arctan2(lidar2world[1, 0], lidar2world[0, 0])
    candidates = cone_candidates(lidar2world[:3, 3], corners, 32,
                                 elevations, 64, 0.01, yaw)
    culled = cast_rays(lidar2world[:3, 3], dirs, candidates=candidates,
                       **shape)
    brute = cast_rays(lidar2world[:3, 3], dirs, **shape)
    assert np.array_equal(culled.target, brute.target)
    assert (brute.target >= 0).sum() > 100


def test_objects_never_collide():
    """Over a 10 s scene (sampled every 1.25 s), no two objects' footprints
    overlap (buildings and vegetation aside, which may touch) and no object
    enters the ego's 5 m x 2 m footprint: moving vehicles keep to their
    lanes at one speed per lane, pedestrians to their bands."""
    world = build_world(np.random.default_rng(1), 10.0, False, True)
    boxes = world.boxes
    things = np.nonzero(~np.isin(boxes.raw_class, (28, 30)))[0]
    radius = np.linalg.norm(boxes.size[things, :2], axis=1) / 2
    for t in np.linspace(0, 10, 9):
        corners = boxes.corners_at(t)[things][:, [0, 2, 6, 4], :2]
        shapes = [Polygon(c) for c in corners]
        ego = world.ego_pose(t)
        footprint = Polygon(
            [ego[:2, :2] @ np.array(p) + ego[:2, 3]
             for p in ((-1, -1), (4, -1), (4, 1), (-1, 1))])
        assert not any(shape.intersects(footprint) for shape in shapes)
        centre = corners.mean(axis=1)
        near = np.linalg.norm(centre[:, None] - centre[None], axis=2) < (
            radius[:, None] + radius[None])
        for i, j in zip(*np.nonzero(np.triu(near, 1))):
            assert shapes[i].intersection(shapes[j]).area < 1e-6, (
                boxes.attribute[things[i]], boxes.attribute[things[j]])


@pytest.mark.parametrize('seed', range(8))
def test_every_scene_shows_every_object_class(seed):
    """Each scene has a bus, a trailer, a motorcycle, a bicycle and a bench
    ("others") whose centre is within 35 m of the ego at mid-scene, well
    inside both label ranges, so a 2-scene val split measures every class.
    The layout starts each within 20 m of the ego's road position; half a
    bus (6 m) along the road, up to 8 m sideways and, for a bicycle or
    bench, one sidewalk slot (12-25 m) past a cross street add to that
    (worst of 60 seeds: 34.4 m). Before the layout placed them, 8 of these
    8 scenes missed at least one of the five within 30 m."""
    duration = 3.45  # 8 key frames, 10 sweeps each
    world = build_world(np.random.default_rng([seed, 0, 0]), duration,
                        False, False)
    boxes = world.boxes
    ego = world.ego_pose(duration / 2)[:2, 3]
    centre = boxes.center[:, :2] + boxes.velocity * duration / 2
    near = np.linalg.norm(centre - ego, axis=1) < 35.0
    for raw in (16, 22, 21, 14, 29):  # bus, trailer, motorcycle, bicycle,
        assert (near & (boxes.raw_class == raw)).any(), raw  # bench


def test_empty_world_is_just_ground():
    """A world without boxes, ego at the origin, sensor jitter off.

    * Occ3D grid: only the ground layer z in [-0.2, 0.2] (index 2) is
      occupied: 200 * 200 = 40000 voxels, every one a ground class.
    * LiDAR (16 azimuth steps): the 32 beams are -30.67 + 41.34 k / 31 deg;
      beam k reaches the ground (1.84 m below) within 70 m iff
      sin(-elevation) >= 1.84 / 70, i.e. elevation <= -1.51 deg, which
      holds for k <= 21 (k = 21: -2.67 deg; k = 22: -1.34 deg, 79 m). So
      beams 0..21 return 22 * 16 = 352 points at z = -1.84 (ground or a
      spurious return replacing it); higher beams return only spurious
      'noise' points.
    * Camera: sees only ground classes and sky (0).
    """
    world = build_world(np.random.default_rng(2), 1.0, False, False)
    empty = Boxes(center=np.zeros((0, 3)), size=np.zeros((0, 3)),
                  yaw=np.zeros(0), velocity=np.zeros((0, 2)),
                  raw_class=np.zeros(0, np.uint8), colour=np.zeros((0, 3)),
                  annotated=np.zeros(0, bool), attribute=[])
    world = dataclasses.replace(world, boxes=empty)
    ego_pose = world.ego_pose(0.0)
    raw = voxelize(world, 0.0, ego_pose, OCC3D_GRID)
    occupied = np.argwhere(raw != RAW_FREE)
    assert len(occupied) == 40000 and set(occupied[:, 2]) == {2}
    assert set(np.unique(raw[raw != RAW_FREE])) <= {24, 25, 26, 27}
    sweep = scan_lidar(world, ego_pose @ make_lidar2ego(), 0.0, 16,
                       np.random.default_rng(0))
    ring = sweep.points[:, 4]
    low = ring <= 21
    assert low.sum() == 352
    ground = low & (sweep.raw_class != 0)
    assert np.abs(sweep.points[ground, 2] + 1.84).max() < 0.05
    assert (sweep.raw_class[~low] == 0).all()
    camera = make_camera_rig((32, 18))[0]
    rendered = render_camera(world, camera, ego_pose, 0.0)
    assert set(np.unique(rendered['raw_class'])) <= {0, 24, 25, 26, 27}
    assert rendered['box_visible'].shape == (0, )


def test_devkit_loads_the_tiny_world(tiny_root, nusc):
    """1 scene, 2 samples, each with the 6 cameras and LIDAR_TOP; every key
    frame reaches >= 10 earlier sweeps through prev, 50 ms apart (20 Hz);
    the map, annotations and meta data are there."""
    assert len(nusc.scene) == 1 and len(nusc.sample) == 2
    for sample in nusc.sample:
        assert set(sample['data']) == set(CAMERA_NAMES) | {'LIDAR_TOP'}
        sd = nusc.get('sample_data', sample['data']['LIDAR_TOP'])
        assert sd['timestamp'] == sample['timestamp']
        times = [sd['timestamp']]
        while sd['prev']:
            sd = nusc.get('sample_data', sd['prev'])
            times.append(sd['timestamp'])
            assert osp.isfile(osp.join(tiny_root, sd['filename']))
        assert len(times) >= 11
        assert set(np.diff(times).tolist()) == {-50000}
        for cam in CAMERA_NAMES:
            cam_sd = nusc.get('sample_data', sample['data'][cam])
            image = cv2.imread(osp.join(tiny_root, cam_sd['filename']))
            assert image.shape == (90, 160, 3)
            intrinsic = np.array(nusc.get(
                'calibrated_sensor',
                cam_sd['calibrated_sensor_token'])['camera_intrinsic'])
            # nuScenes' 1257..1273 px at 1600 wide -> 125.7..127.3 px at
            # 160; CAM_BACK's 809.2 -> 80.9.
            expected = 80.9 if cam == 'CAM_BACK' else 126.5
            assert intrinsic[0, 0] == pytest.approx(expected, abs=0.9)
    # The semantic prior map is georeferenced at 0.1 m / pixel: the ego
    # drives on it, terrain 30 m to its side is off it.
    pose = nusc.get('ego_pose', nusc.get(
        'sample_data', nusc.sample[0]['data']['LIDAR_TOP'])['ego_pose_token'])
    log = nusc.get('log', nusc.scene[0]['log_token'])
    map_mask = nusc.get('map', log['map_token'])['mask']
    x, y = pose['translation'][:2]
    left = Quaternion(pose['rotation']).rotation_matrix[:2, 1]
    assert map_mask.is_on_mask(x, y)
    assert not map_mask.is_on_mask(x + 30 * left[0], y + 30 * left[1])
    assert len(nusc.sample_annotation) > 0
    ann = nusc.sample_annotation[0]
    assert len(ann['size']) == 3 and len(ann['rotation']) == 4
    with open(osp.join(tiny_root, META_PATH)) as f:
        assert json.load(f)['complete']


def test_lidarseg_has_one_label_per_point(tiny_root, nusc):
    """Key-frame sweeps are float32 (N, 5) x, y, z, intensity, ring with
    rings 0..31; the lidarseg .bin has exactly N uint8 labels."""
    for sample in nusc.sample:
        token = sample['data']['LIDAR_TOP']
        points = _load_points(tiny_root, nusc.get('sample_data', token))
        labels = np.fromfile(osp.join(
            tiny_root, nusc.get('lidarseg', token)['filename']), np.uint8)
        assert len(points) > 1000 and len(labels) == len(points)
        assert set(np.unique(points[:, 4])) <= set(range(32))
        assert points[:, 3].min() >= 0 and points[:, 3].max() <= 255
        assert labels.max() < 32


def test_points_land_on_pixels_of_their_class(tiny_root, nusc):
    """Key-frame points projected through the devkit's calibration (LiDAR
    -> ego -> global -> ego -> camera -> K) land on pixels whose rendered
    raw class equals their lidarseg label for >= 90 % of the points (the
    rest: parallax between LiDAR and camera at object edges)."""
    matches, total = 0, 0
    for sample in nusc.sample:
        lidar2global, _, lidar_sd = _sensor2global(
            nusc, sample['data']['LIDAR_TOP'])
        points = _load_points(tiny_root, lidar_sd)
        labels = np.fromfile(osp.join(tiny_root, nusc.get(
            'lidarseg', lidar_sd['token'])['filename']), np.uint8)
        world_points = _apply(lidar2global, points[:, :3])
        for cam in CAMERA_NAMES:
            cam2global, cam2ego, cam_sd = _sensor2global(
                nusc, sample['data'][cam])
            cam_points = _apply(np.linalg.inv(cam2global), world_points)
            intrinsic = np.array(nusc.get(
                'calibrated_sensor',
                cam_sd['calibrated_sensor_token'])['camera_intrinsic'])
            depth = cam_points[:, 2]
            front = depth > 0.5
            uv = cam_points[front] @ intrinsic.T
            # Pixel (u, v) covers [u, u + 1) x [v, v + 1).
            uv = np.floor(uv[:, :2] / uv[:, 2:]).astype(int)
            inside = ((uv[:, 0] >= 0) & (uv[:, 0] < cam_sd['width'])
                      & (uv[:, 1] >= 0) & (uv[:, 1] < cam_sd['height']))
            class_map = cv2.imread(osp.join(
                tiny_root, camera_label_path(cam_sd['filename'])),
                cv2.IMREAD_UNCHANGED)
            seen = class_map[uv[inside, 1], uv[inside, 0]]
            point_labels = labels[front][inside]
            valid = point_labels != 0  # spurious returns are 'noise'
            matches += int((seen[valid] == point_labels[valid]).sum())
            total += int(valid.sum())
    assert total > 1000
    assert matches / total >= 0.9


def test_sweeps_lie_on_the_world_surfaces(tiny_root, nusc, world):
    """Every sweep's points (key frames and the 10 earlier sweeps), moved to
    the global frame with the devkit's ego pose and calibration, lie within
    5 cm (5 sigma of the range noise) of the ground or of a box surface at
    the sweep's time, except spurious returns (< 3 %)."""
    first = nusc.get('sample_data',
                     nusc.sample[0]['data']['LIDAR_TOP'])
    while first['prev']:
        first = nusc.get('sample_data', first['prev'])
    sd, checked = first, 0
    while True:
        lidar2global, _, _ = _sensor2global(nusc, sd['token'])
        points = _apply(lidar2global, _load_points(tiny_root, sd)[:, :3])
        t = (sd['timestamp'] - first['timestamp']) / 1e6
        distance = np.minimum(np.abs(points[:, 2]),
                              _box_surface_distance(world, points, t))
        assert (distance < 0.05).mean() > 0.97, sd['filename']
        checked += 1
        if not sd['next']:
            break
        sd = nusc.get('sample_data', sd['next'])
    assert checked == 21


def _voxel_centres(grid, index):
    return np.asarray(grid.lower) + (index + 0.5) * grid.voxel_size


def test_known_object_occupies_its_voxels(tiny_root, nusc):
    """Voxels whose whole extent lies inside an annotated car (the box
    shrunk by half a voxel diagonal) carry label 4 (car) in SurroundOcc's
    LiDAR-frame grid and in Occ3D's ego-frame grid."""
    sample = nusc.sample[0]
    lidar2global, lidar2ego, lidar_sd = _sensor2global(
        nusc, sample['data']['LIDAR_TOP'])
    ego2global = lidar2global @ np.linalg.inv(lidar2ego)
    sparse = np.load(osp.join(tiny_root, 'nuscenes_occ', 'samples',
                              osp.basename(lidar_sd['filename']) + '.npy'))
    surround = np.zeros(SURROUNDOCC_GRID.shape, np.int64) - 1
    surround[tuple(sparse[:, :3].T)] = sparse[:, 3]
    occ3d = np.load(osp.join(tiny_root, 'gts', 'scene-0001',
                             sample['token'], 'labels.npz'))['semantics']
    cars = [nusc.get('sample_annotation', a) for a in sample['anns']]
    cars = [a for a in cars if a['category_name'] == 'vehicle.car']
    checked = 0
    for ann in cars:
        box2global = np.eye(4)
        box2global[:3, :3] = Quaternion(ann['rotation']).rotation_matrix
        box2global[:3, 3] = ann['translation']
        half = np.array([ann['size'][1], ann['size'][0], ann['size'][2]]) / 2
        for grid, labels, grid2global in (
                (SURROUNDOCC_GRID, surround, lidar2global),
                (OCC3D_GRID, occ3d, ego2global)):
            # The voxels of an 8 m cube around the car, clipped to the grid.
            centre = _apply(np.linalg.inv(grid2global), np.array(
                [ann['translation']]))[0]
            lo = np.floor((centre - 4 - grid.lower) / grid.voxel_size)
            hi = np.ceil((centre + 4 - grid.lower) / grid.voxel_size)
            axes = [np.arange(max(lo[a], 0), min(hi[a], grid.shape[a]),
                              dtype=int) for a in range(3)]
            index = np.stack(np.meshgrid(*axes, indexing='ij'),
                             -1).reshape(-1, 3)
            local = _apply(np.linalg.inv(box2global) @ grid2global,
                           _voxel_centres(grid, index))
            margin = grid.voxel_size * np.sqrt(3) / 2
            deep = (np.abs(local) <= half - margin).all(axis=1)
            if not deep.any():
                continue
            assert (labels[tuple(index[deep].T)] == 4).all()
            checked += 1
    assert checked >= 2


def test_occupancy_files_have_the_documented_format(tiny_root, nusc):
    """SurroundOcc: int (N, 4) unique indices inside 200x200x16, labels
    0..16. Occ3D: uint8 (200, 200, 16) semantics 0..17 and 0/1 masks."""
    for sample in nusc.sample:
        lidar_sd = nusc.get('sample_data', sample['data']['LIDAR_TOP'])
        sparse = np.load(osp.join(
            tiny_root, 'nuscenes_occ', 'samples',
            osp.basename(lidar_sd['filename']) + '.npy'))
        assert np.issubdtype(sparse.dtype, np.integer)
        assert sparse.ndim == 2 and sparse.shape[1] == 4
        assert (sparse[:, :3] >= 0).all()
        assert (sparse[:, :3] < np.array([200, 200, 16])).all()
        assert len(np.unique(sparse[:, :3], axis=0)) == len(sparse)
        assert sparse[:, 3].max() <= 16
        labels = np.load(osp.join(tiny_root, 'gts', 'scene-0001',
                                  sample['token'], 'labels.npz'))
        assert set(labels.files) == {'semantics', 'mask_lidar',
                                     'mask_camera'}
        for key in labels.files:
            assert labels[key].shape == (200, 200, 16)
            assert labels[key].dtype == np.uint8
        assert labels['semantics'].max() == OCC3D_FREE_LABEL
        assert set(np.unique(labels['mask_camera'])) == {0, 1}
        # The ground layer is z in [-0.2, 0.2] (index 2) in the ego frame.
        ground = labels['semantics'][:, :, 2]
        assert (ground != OCC3D_FREE_LABEL).mean() > 0.9


def test_lidar_mask_covers_every_return(tiny_root, nusc):
    """mask_lidar holds the voxel of (almost: float32 rounding of points on
    voxel faces) every key-frame point inside the Occ3D range, the key
    frame being one of the aggregated sweeps."""
    for sample in nusc.sample:
        lidar2global, lidar2ego, lidar_sd = _sensor2global(
            nusc, sample['data']['LIDAR_TOP'])
        points = _apply(lidar2ego, _load_points(tiny_root, lidar_sd)[:, :3])
        index = np.floor((points - OCC3D_GRID.lower) / 0.4).astype(int)
        inside = ((index >= 0) & (index < OCC3D_GRID.shape)).all(axis=1)
        mask = np.load(osp.join(tiny_root, 'gts', 'scene-0001',
                                sample['token'], 'labels.npz'))['mask_lidar']
        assert inside.sum() > 500
        assert mask[tuple(index[inside].T)].mean() > 0.999
        assert 0.05 < mask.mean() < 0.9


def test_camera_mask_excludes_voxels_behind_buildings(tiny_root, nusc, world):
    """On the voxel layer at camera height (z in [1.4, 1.8] m), free voxels
    whose line of sight to all 6 camera centres crosses a building are not
    in mask_camera (< 5 %), while free voxels within 15 m that CAM_FRONT
    sees unobstructed (inside its image) are (>= 90 %)."""
    sample = nusc.sample[0]
    occ = np.load(osp.join(tiny_root, 'gts', 'scene-0001', sample['token'],
                           'labels.npz'))
    layer = 6  # -1 + 6 * 0.4 = 1.4 .. 1.8 m
    free = np.argwhere(occ['semantics'][:, :, layer] == OCC3D_FREE_LABEL)
    index = np.concatenate([free, np.full((len(free), 1), layer)], axis=1)
    lidar2global, lidar2ego, _ = _sensor2global(
        nusc, sample['data']['LIDAR_TOP'])
    ego2global = lidar2global @ np.linalg.inv(lidar2ego)
    targets = _apply(ego2global, _voxel_centres(OCC3D_GRID, index))
    boxes = world.boxes
    t = 10 * 0.05  # the first key frame follows 10 sweeps
    building = boxes.raw_class == 28
    hidden = np.ones(len(targets), bool)
    for cam in CAMERA_NAMES:
        cam2global, _, _ = _sensor2global(nusc, sample['data'][cam])
        origin = cam2global[:3, 3]
        hits = cast_rays(origin, targets - origin,
                         boxes.centers_at(t)[building], boxes.size[building],
                         boxes.yaw[building], ground=False)
        hidden &= hits.t < 0.98
    mask = occ['mask_camera'][:, :, layer][free[:, 0], free[:, 1]]
    assert hidden.sum() > 100
    assert mask[hidden].mean() < 0.05
    cam2global, _, cam_sd = _sensor2global(nusc, sample['data']['CAM_FRONT'])
    origin = cam2global[:3, 3]
    near = np.linalg.norm(targets - origin, axis=1) < 15
    cam_points = _apply(np.linalg.inv(cam2global), targets[near])
    intrinsic = np.array(nusc.get(
        'calibrated_sensor',
        cam_sd['calibrated_sensor_token'])['camera_intrinsic'])
    uv = cam_points @ intrinsic.T
    in_view = (cam_points[:, 2] > 1) & (np.abs(
        uv[:, 0] / uv[:, 2] - 80) < 75) & (np.abs(uv[:, 1] / uv[:, 2] - 45)
                                           < 40)
    rays = targets[near][in_view] - origin
    hits = cast_rays(origin, rays, boxes.centers_at(t), boxes.size,
                     boxes.yaw, ground=False)
    clear = hits.t > 1.02
    seen = mask[near][in_view][clear]
    assert len(seen) > 50 and seen.mean() >= 0.9


@pytest.fixture(scope='module')
def weather_root(tmp_path_factory):
    return make_tiny_world(str(tmp_path_factory.mktemp('weather')),
                           num_scenes=3, samples_per_scene=1,
                           sweeps_per_sample=1,
                           conditions=['clear', 'rain', 'night'],
                           image_size=(64, 36), azimuth_bins=16)


def test_weather_descriptions_and_night_images(weather_root):
    """Scene descriptions mention 'rain' / 'night' exactly when asked, like
    nuScenes' ('Night, ...', 'Rain, ...'); the night CAM_FRONT image is
    much darker (mean < 0.6x) than the clear day one."""
    nusc = NuScenes(version='v1.0-mini', dataroot=weather_root,
                    verbose=False)
    description = {s['name']: s['description'].lower() for s in nusc.scene}
    flags = [('rain' in description[f'scene-000{i}'],
              'night' in description[f'scene-000{i}']) for i in (1, 2, 3)]
    assert flags == [(False, False), (True, False), (False, True)]
    means = []
    for scene in nusc.scene:
        sample = nusc.get('sample', scene['first_sample_token'])
        sd = nusc.get('sample_data', sample['data']['CAM_FRONT'])
        means.append(cv2.imread(osp.join(weather_root,
                                         sd['filename'])).mean())
    assert means[2] < 0.6 * means[0]


def _digest(root):
    digest = hashlib.md5()
    for path in sorted(glob.glob(osp.join(root, '**', '*'), recursive=True)):
        if osp.isfile(path) and not path.endswith('meta.json'):
            digest.update(osp.relpath(path, root).encode())
            with open(path, 'rb') as f:
                digest.update(f.read())
    return digest.hexdigest()


def test_same_seed_same_bytes(tmp_path):
    """Two runs with seed 0 write identical files; seed 1 lays out another
    world."""
    kwargs = dict(num_scenes=1, samples_per_scene=1, sweeps_per_sample=2,
                  image_size=(32, 18), azimuth_bins=16)
    for name in 'ab':
        generate_synthetic_nuscenes(str(tmp_path / name), seed=0, **kwargs)
    assert _digest(str(tmp_path / 'a')) == _digest(str(tmp_path / 'b'))
    worlds = [build_world(np.random.default_rng([seed, 0, 0]), 1.0, False,
                          False) for seed in (0, 1)]
    assert len(worlds[0].boxes) != len(worlds[1].boxes) or not np.allclose(
        worlds[0].boxes.center, worlds[1].boxes.center)


def test_bad_arguments_and_existing_data_raise(tmp_path):
    """Out-of-range arguments raise ValueError naming the argument; an
    existing world is kept unless overwrite=True; a folder with nuScenes
    data this generator did not write is never overwritten."""
    out = str(tmp_path / 'w')
    for kwargs, message in ((dict(num_scenes=0), 'num_scenes'),
                            (dict(image_size=(4, 4)), 'image_size'),
                            (dict(version='a/b'), 'version'),
                            (dict(conditions=['fog']), 'conditions')):
        with pytest.raises(ValueError, match=message):
            generate_synthetic_nuscenes(out, num_scenes=kwargs.pop(
                'num_scenes', 1), **kwargs)
    tiny = dict(num_scenes=1, samples_per_scene=1, sweeps_per_sample=1,
                image_size=(32, 18), azimuth_bins=16)
    generate_synthetic_nuscenes(out, **tiny)
    with pytest.raises(FileExistsError, match='overwrite'):
        generate_synthetic_nuscenes(out, **tiny)
    summary = generate_synthetic_nuscenes(out, overwrite=True, **tiny)
    assert summary['num_samples'] == 1 and summary['num_sweeps'] == 11
    with pytest.raises(FileNotFoundError, match='scene-0009'):
        load_world(out, 'scene-0009')
    real = str(tmp_path / 'real')
    os.makedirs(osp.join(real, 'v1.0-mini'))
    with pytest.raises(FileExistsError, match='not a synthetic world'):
        generate_synthetic_nuscenes(real, overwrite=True, **tiny)
    assert osp.isdir(osp.join(real, 'v1.0-mini'))


def test_command_line(tmp_path, capsys):
    """The CLI writes the world, shows the progress of its sweeps on
    stderr (1 scene: 10 sweeps before the first key frame, then 1: 11)
    and prints its summary as JSON on stdout."""
    tool = runpy.run_path(
        osp.join(ROOT, 'tools', 'dataset_converters',
                 'create_synthetic_nuscenes.py'))
    out = str(tmp_path / 'cli')
    tool['main']([out, '--scenes', '1', '--samples', '1', '--sweeps', '2',
                  '--image-size', '32', '18', '--azimuth-bins', '16',
                  '--seed', '3'])
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert '11/11' in captured.err
    assert summary['num_samples'] == 1 and summary['num_images'] == 6
    assert summary['seed'] == 3
    assert osp.isfile(osp.join(out, 'v1.0-mini', 'scene.json'))
