"""The real nuScenes key frame of ``../shared`` through the whole chain.

mmdet3d's own info file of the sample is extended by
``tools/create_data.py --from-mmdet3d-info`` and the result is loaded by
the dataset with the base configs' test inputs: the car's returns go, the
rest of the file arrives unchanged, and the depth maps agree with an
independent numpy projection of the raw file with mmdet3d's calibration.
The synthetic world tests the same code paths elsewhere; this shows they
hold on real calibration (LiDAR at yaw -90 deg, six real cameras).
"""
import glob
import os.path as osp

import numpy as np
import pytest
import torch
from mmdet3d.registry import DATASETS, MODELS
from mmdet3d.utils import register_all_modules
from mmengine.config import Config

import projects.occ_common  # noqa: F401  (registers)
from projects.occ_common.datasets.info_format import CAMERA_NAMES
from projects.occ_common.fileio.safe_pickle import load_info_file
from projects.occ_common.geometry.depth import (depth_bin_values,
                                                depth_to_bins, patch_min_depth)
from projects.occ_common.testing.tool_logs import run_create_data

register_all_modules(init_default_scope=True)
REPO = osp.dirname(osp.dirname(osp.dirname(osp.dirname(__file__))))
REAL = osp.join(REPO, '..', 'shared', 'data', 'nuscenes_real_sample')
MMDET3D_INFO = osp.join(REAL, 'n015-2018-07-24-11-22-45+0800.pkl')
pytestmark = [
    pytest.mark.skipif(
        not osp.isfile(MMDET3D_INFO),
        reason='the real nuScenes sample (../shared/data/'
        'nuscenes_real_sample) is absent; a user clone has no ../shared'),
    pytest.mark.filterwarnings('ignore:.*label folder .* not found'),
    pytest.mark.filterwarnings('ignore:.*scene unknown'),
]
#: Points of the file, and those on the car (tests/occ_common/transforms/
#: test_ego_points.py counts them from the raw file).
NUM_POINTS, NUM_EGO = 34688, 8526


@pytest.fixture(scope='module')
def real_info(tmp_path_factory):
    """Our info file of the sample, extended from mmdet3d's."""
    out = str(tmp_path_factory.mktemp('real_info'))
    written = run_create_data('--root-path', REAL, '--out-dir', out,
                              '--from-mmdet3d-info', MMDET3D_INFO)
    return written['n015-2018-07-24-11-22-45+0800']


def _inputs_dataset(real_info, pipeline_tail=()):
    """The SurroundOcc base's test inputs (no labels: the sample has
    none) on the real sample, then ``pipeline_tail``."""
    cfg = Config.fromfile(
        osp.join(REPO, 'configs', '_base_', 'datasets',
                 'surroundocc-nus.py'))
    ds_cfg = cfg.val_dataloader.dataset
    ds_cfg.data_root = REAL
    ds_cfg.ann_file = real_info
    ds_cfg.pipeline = list(cfg.test_inputs) + list(pipeline_tail)
    return DATASETS.build(ds_cfg)


def test_extended_info_keeps_mmdet3d_calibration(real_info):
    """The extension links the flat folder's files and copies every matrix
    of mmdet3d's info bit for bit; labels and scene are unknown."""
    ours = load_info_file(real_info)['data_list'][0]
    theirs = load_info_file(MMDET3D_INFO)['data_list'][0]
    assert ours['token'] == theirs['token'] == \
        'ca9a282c9e77460f8360f564131a8af5'
    assert ours['lidar_points']['lidar_path'] == \
        theirs['lidar_points']['lidar_path']
    np.testing.assert_array_equal(ours['lidar_points']['lidar2ego'],
                                  theirs['lidar_points']['lidar2ego'])
    for cam in CAMERA_NAMES:
        for key in ('cam2img', 'lidar2cam', 'cam2ego'):
            np.testing.assert_array_equal(ours['images'][cam][key],
                                          theirs['images'][cam][key])
        assert osp.isfile(osp.join(REAL, ours['images'][cam]['img_path']))
    assert ours['lidar_sweeps'] == []
    assert ours['occ_surroundocc_path'] is None is ours['occ_occ3d_path']
    assert ours['scene_name'] is None and not ours['is_rainy']


def test_pipeline_drops_the_car_and_keeps_the_rest(real_info):
    """Through the dataset: 34,688 - 8,526 = 26,162 points, each a row
    of the file (x, y, z, intensity as read; column 4 the time lag 0 in
    place of the ring index, as the sweep merge documents), and six
    256x704 images."""
    out = _inputs_dataset(real_info, [dict(type='PackOccInputs')])[0]
    points = out['inputs']['points'].numpy()
    meta = out['data_samples'].metainfo
    raw = np.fromfile(osp.join(REAL, meta['lidar_path']),
                      np.float32).reshape(-1, 5)
    assert len(raw) == NUM_POINTS
    assert meta['num_ego_points'] == NUM_EGO
    assert len(points) == NUM_POINTS - NUM_EGO
    assert (points[:, 4] == 0).all()
    rows = {r[:4].tobytes() for r in raw}
    assert all(p[:4].tobytes() in rows for p in points)
    assert 0 <= points[:, 3].min() and points[:, 3].max() <= 255
    assert out['inputs']['img'].shape == (6, 3, 256, 704)


def test_depth_maps_match_an_independent_projection(real_info):
    """The pipeline's depth maps (PointsToDepthMaps after the test image
    resize / crop) against numpy: p_cam = lidar2cam @ p, (u, v) = K p_cam
    / z from mmdet3d's own matrices, then BEVDet's test crop of the
    1600x900 image to 704x256 (scale 0.44 -> 704x396, bottom 256 rows:
    v - 140), pixel = floor, nearest point per pixel. Every pixel agrees
    (measured: the same 19,565 pixels hit, 2,795 .. 4,552 per view, with
    identical depths)."""
    state = _inputs_dataset(
        real_info, [dict(type='PointsToDepthMaps')]).prepare_data(0)
    ours = state['gt_depth']
    theirs_info = load_info_file(MMDET3D_INFO)['data_list'][0]
    raw = np.fromfile(
        osp.join(REAL, theirs_info['lidar_points']['lidar_path']),
        np.float32).reshape(-1, 5)
    kept = state['points'].tensor.numpy()[:, :3].astype(np.float64)
    expected = np.zeros_like(ours)
    for view, cam in enumerate(state['cam_names']):
        image = theirs_info['images'][cam]
        cam_pts = kept @ np.asarray(image['lidar2cam'])[:3, :3].T + \
            np.asarray(image['lidar2cam'])[:3, 3]
        z = cam_pts[:, 2]
        uvw = cam_pts @ np.asarray(image['cam2img'])[:3, :3].T
        front = z > 1e-3
        u = np.floor(uvw[front, 0] / z[front] * 0.44)
        v = np.floor(uvw[front, 1] / z[front] * 0.44 - 140)
        depth = z[front]
        hit = (u >= 0) & (u < 704) & (v >= 0) & (v < 256)
        # Farthest first, so the nearest point of a pixel is written last.
        order = np.argsort(-depth[hit], kind='stable')
        expected[view, v[hit][order].astype(int),
                 u[hit][order].astype(int)] = depth[hit][order]
    assert len(raw) == NUM_POINTS
    hit = expected > 0
    assert hit.sum() == 19565
    np.testing.assert_array_equal(ours > 0, hit)
    np.testing.assert_allclose(ours[hit], expected[hit], atol=1e-5)


def test_nearest_bin_lifts_real_lidar_depths_without_bias(real_info):
    """The paper's 1 m bins (1, 2, ..., 50 m) on the real depth maps at
    stride 16: BEVDepth's floor trains the 3,860 feature pixels with a
    LiDAR depth onto bin points 0.516 m closer on average (every one
    closer: the mean absolute error is the same), nearest_bin onto points
    +0.014 m off on average, 0.247 m in absolute value (about a quarter
    bin, as for uniform depths). Measured on the sample."""
    state = _inputs_dataset(
        real_info, [dict(type='PointsToDepthMaps')]).prepare_data(0)
    gt = torch.as_tensor(state['gt_depth']).float()
    bound = (1.0, 51.0, 1.0)
    depth = patch_min_depth(gt, 16).reshape(-1)
    errors = {}
    for nearest in (False, True):
        onehot, valid = depth_to_bins(gt, 16, bound, nearest_bin=nearest)
        lifted = depth_bin_values(bound)[onehot.argmax(1)]
        errors[nearest] = (lifted - depth)[valid]
    assert errors[False].numel() == 3860
    assert float(errors[False].mean()) == pytest.approx(-0.516, abs=1e-3)
    assert float(errors[False].max()) <= 0
    assert abs(float(errors[True].mean())) < 0.02
    assert float(errors[True].abs().mean()) == pytest.approx(0.247, abs=1e-3)


def test_depth_bin_accuracy_of_an_oracle_on_the_real_depths(real_info):
    """tools/analysis_tools/depth_accuracy.py's measure on the real sample's
    depth maps
    (the paper's 1 m bins, stride 16), with the one-hot of the nearest
    bins as the prediction: all 3,856 pixels with a return right (the
    3,860 of the test above less the 4 whose nearest return lies between
    50.5 and 51 m, beyond the last bin point's half-bin), and their
    feature mass 0.247 m from the surface on average, the nearest bin's
    rounding error of the test above; a uniform prediction puts 1/50 on
    the right bin."""
    from projects.occ_common.evaluation import DepthBinAccuracy
    state = _inputs_dataset(
        real_info, [dict(type='PointsToDepthMaps')]).prepare_data(0)
    gt = torch.as_tensor(state['gt_depth']).float()
    bound = (1.0, 51.0, 1.0)
    onehot, _ = depth_to_bins(gt, 16, bound, nearest_bin=True)
    num, height, width = gt.shape[0], gt.shape[1] // 16, gt.shape[2] // 16
    oracle = onehot.reshape(num, height, width, 50).permute(0, 3, 1, 2)
    perfect, uniform = DepthBinAccuracy(bound), DepthBinAccuracy(bound)
    perfect.update(oracle, gt)
    uniform.update(torch.full_like(oracle, 1 / 50), gt)
    out = perfect.summary()
    assert out['cells'] == 3856 and out['top1'] == 100.0
    assert out['expected_error_m'] == pytest.approx(0.247, abs=1e-3)
    assert uniform.summary()['prob_true'] == pytest.approx(0.02)


#: Of the nuScenes rig (the four-camera rig's configs name other cameras).
TINY = sorted(p for p in glob.glob(osp.join(REPO, 'configs', '*',
                                            '*_tiny_*.py'))
              if '-quad-' not in p)
#: The label steps of the test pipelines: the sample has no labels.
LABEL_STEPS = ('LoadOccupancyGT', 'PointsToSemanticMaps')


@pytest.mark.parametrize('path', TINY, ids=lambda p: osp.basename(p)[:-3])
def test_tiny_configs_predict_on_the_real_sample(real_info, path):
    """Every tiny config (untrained weights) runs predict on the real
    sample through its own test pipeline without the label steps: six real
    images resized to its size, the real points (without the car, within
    its grid); the prediction is one label per voxel of the 200x200x16
    grid, finite logits, the class count of its dataset."""
    from mmengine.dataset import pseudo_collate
    from mmengine.registry import init_default_scope
    cfg = Config.fromfile(path)
    for module in cfg.custom_imports['imports']:
        __import__(module)
    init_default_scope('mmdet3d')
    ds_cfg = cfg.test_dataloader.dataset
    ds_cfg.data_root = REAL
    ds_cfg.ann_file = real_info
    ds_cfg.pipeline = [t for t in cfg.test_pipeline
                       if t['type'] not in LABEL_STEPS]
    sample = DATASETS.build(ds_cfg)[0]
    assert sample['data_samples'].metainfo['num_ego_points'] == NUM_EGO
    model = MODELS.build(cfg.model).eval()
    torch.manual_seed(0)
    with torch.no_grad():
        data = model.data_preprocessor(pseudo_collate([sample]), False)
        assert data['inputs']['imgs'].shape[-2:] == tuple(cfg.img_size)
        pred = model(**data, mode='predict')[0].pred_occ
        logits = model(**data, mode='tensor')
    assert tuple(pred.shape) == (200, 200, 16)
    assert 0 <= int(pred.min()) and int(pred.max()) < cfg.num_classes
    first = logits[0] if isinstance(logits, (list, tuple)) else logits
    first = first[0] if isinstance(first, (list, tuple)) else first
    assert torch.isfinite(first).all()


def test_single_key_frame_repeats_itself_as_its_previous_frame(real_info):
    """The sample has no previous key frame (its info has no link): with
    num_frames=2 its previous frame is itself, so the packed sample holds
    the six 256x704 views twice, identical, prev2curr is the identity and
    the previous matrices are the current ones. With the config's ego box
    the previous frame's points are the current ones (26,162 of the file's
    34,688); without it all 34,688."""
    assert load_info_file(real_info)['data_list'][0]['prev_key_frame'] \
        is None
    cfg = Config.fromfile(
        osp.join(REPO, 'configs', '_base_', 'datasets',
                 'surroundocc-nus.py'))
    ds_cfg = cfg.val_dataloader.dataset
    ds_cfg.update(data_root=REAL, ann_file=real_info, num_frames=2)
    previous = dict(type='LoadPreviousKeyFrames', num_frames=2,
                    load_points=True)
    ds_cfg.pipeline = list(cfg.test_inputs) + [
        dict(previous, ego_box=cfg.ego_box), dict(type='PackOccInputs')
    ]
    out = DATASETS.build(ds_cfg)[0]
    img = out['inputs']['img']
    meta = out['data_samples'].metainfo
    assert img.shape == (12, 3, 256, 704)
    assert torch.equal(img[:6], img[6:])
    assert meta['prev_tokens'] == ['ca9a282c9e77460f8360f564131a8af5']
    np.testing.assert_allclose(meta['prev2curr'][0], np.eye(4), atol=1e-6)
    np.testing.assert_allclose(meta['prev_lidar2img'][0], meta['lidar2img'],
                               rtol=1e-6)
    points = out['inputs']['points'].numpy()
    assert len(points) == NUM_POINTS - NUM_EGO
    np.testing.assert_array_equal(meta['prev_points'][0][:, :4],
                                  points[:, :4])
    ds_cfg.pipeline[-2] = previous
    meta = DATASETS.build(ds_cfg)[0]['data_samples'].metainfo
    assert len(meta['prev_points'][0]) == NUM_POINTS
