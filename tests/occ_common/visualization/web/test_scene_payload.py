"""The viewer's binary message: sections, errors, points, frusta."""
import numpy as np
import pytest

from projects.occ_common.visualization.palette import (ERROR_PALETTE,
                                                       class_palette)
from projects.occ_common.visualization.web import (encode_sample,
                                                   frustum_corners,
                                                   unpack_message, viewer_meta)
from projects.occ_common.visualization.web.scene_payload import (NOT_DRAWN,
                                                                 error_grid)

#: SurroundOcc labels: 0 empty, 4 car, 11 driveable_surface.
EMPTY, CAR, ROAD = 0, 4, 11


def _grids():
    """A 3 x 2 x 2 GT with two road voxels and a car, and a prediction
    that gets one road voxel right (TP), calls the other a car (wrong
    class), misses the car (FN) and adds a car in empty space (FP); one
    GT voxel is ignored (255) where the prediction says road."""
    gt = np.zeros((3, 2, 2), dtype=np.int64)
    gt[0, 0, 0] = ROAD
    gt[1, 0, 0] = ROAD
    gt[2, 1, 1] = CAR
    gt[0, 1, 1] = 255
    pred = np.zeros_like(gt)
    pred[0, 0, 0] = ROAD        # true positive
    pred[1, 0, 0] = CAR         # wrong class
    pred[2, 0, 1] = CAR         # false positive
    pred[0, 1, 1] = ROAD        # on an ignored voxel: never counted
    return gt, pred


def _scene(**extra):
    gt, pred = _grids()
    return {**dict(name='s0', pc_range=[0, 0, 0, 1.5, 1.0, 1.0],
                   voxel_size=[0.5, 0.5, 0.5], gt_occ=gt, pred_occ=pred),
            **extra}


def test_error_grid_codes_by_hand():
    """Flat C-order indices of (3, 2, 2): (0,0,0) -> 0, (1,0,0) -> 4,
    (2,0,1) -> 9, (2,1,1) -> 11, (0,1,1) -> 3. Codes: 0 TP at 0, 3 wrong
    class at 4, 1 FP at 9, 2 FN at 11; the ignored voxel 3 and the
    empty ones are not drawn."""
    gt, pred = _grids()
    grid = error_grid(pred, gt, 17, EMPTY).ravel()
    expected = np.full(12, NOT_DRAWN)
    expected[[0, 4, 9, 11]] = [0, 3, 1, 2]
    np.testing.assert_array_equal(grid, expected)


def test_message_round_trip():
    """Sections come back as written, counts say 3 GT / 3 predicted
    occupied voxels and one of each error, the probability section holds
    the 4 predicted voxels in C order (flat 0, 3, 4, 9), points are
    centimetres and labels outside 0..254 become 255."""
    gt, pred = _grids()
    prob = np.zeros(gt.shape, dtype=np.float32)
    prob.ravel()[[0, 3, 4, 9]] = [1.0, 0.5, 0.25, 0.9]
    mask_camera = np.zeros(gt.shape, dtype=bool)
    mask_camera[0] = True
    points = np.array([[1.234, -5.0, 0.5, 30.0], [400.0, 0.0, 0.0, 300.0]])
    message, jpegs = encode_sample(
        _scene(pred_prob=prob, mask_camera=mask_camera, points=points,
               point_labels=np.array([CAR, -1]), is_night=True,
               token='tok'), num_classes=17, empty_label=EMPTY)
    header, arrays = unpack_message(message)
    assert jpegs == [] and header['cameras'] == []
    assert header['is_night'] and not header['is_rainy']
    assert header['grid']['shape'] == [3, 2, 2]
    np.testing.assert_array_equal(arrays['gt'], gt.ravel() % 256)
    np.testing.assert_array_equal(arrays['pred'], pred.ravel())
    assert header['counts']['gt'] == 3 and header['counts']['pred'] == 4
    assert header['counts']['errors'] == [1, 1, 1, 1]
    np.testing.assert_array_equal(arrays['prob'], [255, 128, 64, 230])
    np.testing.assert_array_equal(arrays['visibility'].reshape(gt.shape),
                                  mask_camera.astype(np.uint8))
    # 400 m is clipped to int16's 327.67 m; intensity 300 to 255.
    np.testing.assert_array_equal(arrays['points_xyz'].reshape(-1, 3),
                                  [[123, -500, 50], [32767, 0, 0]])
    np.testing.assert_array_equal(arrays['points_intensity'], [30, 255])
    np.testing.assert_array_equal(arrays['points_label'], [CAR, 255])
    for name, (offset, _, _) in header['sections'].items():
        assert offset % 4 == 0, name


def test_empty_sample_has_no_sections():
    """A sample with nothing but its grid geometry (a key frame without
    labels, points or images) is a header only."""
    message, jpegs = encode_sample(
        dict(name='empty', pc_range=[0] * 3 + [1] * 3,
             voxel_size=[0.5] * 3), num_classes=17, empty_label=EMPTY)
    header, arrays = unpack_message(message)
    assert arrays == {} and jpegs == [] and header['grid']['shape'] is None


def test_bad_input_names_the_sample():
    gt, pred = _grids()
    with pytest.raises(ValueError, match=r's0 pred_occ: labels \[40\]'):
        encode_sample(_scene(pred_occ=np.full_like(pred, 40)), 17, EMPTY)
    with pytest.raises(ValueError, match='s0: gt_occ and pred_occ differ'):
        encode_sample(_scene(pred_occ=pred[:2]), 17, EMPTY)
    with pytest.raises(ValueError, match='s0 points: 1 points hold NaN'):
        encode_sample(_scene(points=np.array([[np.nan, 0, 0]])), 17, EMPTY)
    with pytest.raises(ValueError, match=r'\(2,\) point labels for 1'):
        encode_sample(_scene(points=np.zeros((1, 3)),
                             point_labels=np.zeros(2)), 17, EMPTY)


def test_viewer_meta_reuses_the_library_palettes():
    names = ('empty', 'car', 'road')
    meta = viewer_meta(names, 0, num_samples=2)
    assert meta['palette'] == class_palette(names).tolist()
    assert meta['error_palette'] == ERROR_PALETTE.tolist()
    assert meta['num_samples'] == 2 and meta['empty_label'] == 0


def test_frustum_of_a_camera_by_hand():
    """A camera at (1, 2, 3) looking along +x (camera z = world x, camera
    x = world -y, camera y = world -z), fx = fy = 100, principal point
    (50, 25), a 100 x 50 image. At depth 2 pixel (0, 0) is 0.5 * 2 = 1 m
    left (world +y) and 0.25 * 2 = 0.5 m up: (3, 3, 3.5); pixel
    (100, 50) is (3, 1, 2.5)."""
    rotation = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]], float)
    centre = np.array([1.0, 2.0, 3.0])
    lidar2cam = np.eye(4)
    lidar2cam[:3, :3] = rotation
    lidar2cam[:3, 3] = -rotation @ centre
    cam2img = np.eye(4)
    cam2img[:3, :3] = [[100, 0, 50], [0, 100, 25], [0, 0, 1]]
    corners = frustum_corners((cam2img @ lidar2cam)[None], (50, 100), 2.0)
    np.testing.assert_allclose(
        corners[0], [[1, 2, 3], [3, 3, 3.5], [3, 1, 3.5], [3, 1, 2.5],
                     [3, 3, 2.5]], atol=1e-9)
    with pytest.raises(ValueError, match='depth must be positive'):
        frustum_corners((cam2img @ lidar2cam)[None], (50, 100), 0.0)
    with pytest.raises(ValueError, match='singular'):
        frustum_corners(np.zeros((1, 4, 4)) + np.eye(4) * [1, 1, 0, 1],
                        (50, 100), 1.0)
