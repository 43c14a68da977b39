"""Random batches of a config's shapes
(projects/occ_common/synthetic/synthetic_batch.py)."""
import os.path as osp

import numpy as np
import pytest
import torch
from mmengine.config import Config

from projects.occ_common.synthetic import synthetic_batch as sb

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.dirname(
    osp.abspath(__file__)))))
TOY_CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')
SDG_CONFIG = osp.join(ROOT, 'configs', 'sdg_occ',
                      'sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py')


def test_config_without_shapes_is_named():
    """The toy config declares no cameras and no point range."""
    with pytest.raises(ValueError, match='toy_occ.py declares neither'):
        sb.synthetic_batch(Config.fromfile(TOY_CONFIG), 1, None)


def test_lidar_like_cloud_lies_in_range():
    """All points inside the range, on the ground (z = -1.84) or walls."""
    gen = np.random.default_rng(0)
    pc_range = (-40.0, -40.0, -1.0 - 1.0, 40.0, 40.0, 5.4)
    points = sb.lidar_like_cloud(500, pc_range, 5, gen)
    assert points.shape == (500, 5) and points.dtype == np.float32
    assert (points[:, :3] >= np.array(pc_range[:3])).all()
    assert (points[:, :3] < np.array(pc_range[3:])).all()
    assert np.isclose(points[:, 2], -1.84, atol=1e-4).mean() > 0.2


def test_synthetic_cloud_has_one_key_frame_sweep():
    """11 sweeps of 10 points each: 10 points with lag 0 (the key frame),
    then 0.05 s steps up to 0.5 s; the batch names the time column, so
    key-frame-only steps (SDG's depth guidance) see one sweep."""
    points = sb.with_sweep_time(np.zeros((110, 5), np.float32), 11)
    assert (points[:, 4] == 0).sum() == 10
    assert np.allclose(np.unique(points[:, 4]), 0.05 * np.arange(11))
    cfg = Config.fromfile(SDG_CONFIG)
    batch, description = sb.synthetic_batch(cfg, 1, 220)
    assert batch['data_samples'][0].metainfo['points_time_dim'] == 4
    assert int((batch['inputs']['points'][0][:, 4] == 0).sum()) == 20
    assert '220 points in 11 sweeps' in description


def test_synthetic_training_targets():
    """Labels: 90 % empty (index 0 of the config), every one of the 17
    classes present, int64; depth: 2 % of the pixels at 1-60 m."""
    gen = np.random.default_rng(0)
    cfg = Config(dict(model=dict(num_classes=17, empty_index=0)))
    occ = sb.synthetic_labels((40, 40, 8), cfg, gen)
    assert occ.dtype == torch.long and occ.shape == (40, 40, 8)
    assert (occ == 0).float().mean() == pytest.approx(0.9 + 0.1 / 17,
                                                      abs=0.01)
    assert set(occ.unique().tolist()) == set(range(17))
    depth = sb.synthetic_depth(2, (30, 40), gen)
    assert depth.shape == (2, 30, 40) and depth.dtype == torch.float32
    hit = depth > 0
    assert hit.float().mean() == pytest.approx(0.02, abs=0.01)
    assert depth[hit].min() >= 1.0 and depth[hit].max() < 60.0


def test_synthetic_training_batch_has_what_the_losses_read():
    """SDG-Fusion on Occ3D (``--train --synthetic-batch``) reads its
    ``mask_camera`` (loss_mask_key) and the 2-D semantic maps: the mask is
    a bool 200 x 200 x 16 grid, about half set; ``gt_seg_2d`` has a class
    in 1..16 exactly where the depth map has a return and the ignore label
    255 elsewhere. Without labels neither is made."""
    cfg = Config.fromfile(SDG_CONFIG)
    batch, _ = sb.synthetic_batch(cfg, 1, 220, labels=True)
    sample = batch['data_samples'][0]
    mask = sample.mask_camera
    assert mask.dtype == torch.bool and mask.shape == (200, 200, 16)
    assert mask.float().mean() == pytest.approx(0.5, abs=0.01)
    seg, depth = sample.gt_seg_2d, sample.gt_depth
    assert seg.dtype == torch.uint8 and seg.shape == depth.shape
    hit = depth > 0
    assert ((seg != 255) == hit).all()
    assert set(seg[hit].unique().tolist()) == set(range(1, 17))
    plain, _ = sb.synthetic_batch(cfg, 1, 220)
    assert 'mask_camera' not in plain['data_samples'][0]
    assert 'gt_seg_2d' not in plain['data_samples'][0]
    # The point segmentation head's labels: a class in 1..16 on the 20
    # key-frame points (lag 0 of 220 points in 11 sweeps), 255 on the 200
    # sweep points.
    points = batch['inputs']['points'][0]
    labels = sample.gt_pts_seg.pts_semantic_mask
    assert labels.dtype == torch.long and labels.shape == (220, )
    key = points[:, 4] == 0
    assert int(key.sum()) == 20 and (labels[~key] == 255).all()
    assert labels[key].min() >= 1 and labels[key].max() <= 16
    assert 'gt_pts_seg' not in plain['data_samples'][0]


def test_two_frame_batch_carries_the_previous_key_frame():
    """sdgocc-fusion-2f (T = 2, 6 cameras, 10 sweeps): 12 images of
    256 x 704 per sample, one previous frame of the same rig with
    ``prev2curr`` the identity, and 220 // 11 = 20 key-frame points (lag 0)
    for its SDG lift."""
    cfg = Config.fromfile(
        osp.join(ROOT, 'configs', 'sdg_occ',
                 'sdgocc-fusion-2f_r50_4xb2-24e_occ3d-nus.py'))
    batch, description = sb.synthetic_batch(cfg, 2, 220)
    assert batch['inputs']['img'][0].shape == (12, 3, 256, 704)
    meta = batch['data_samples'][1].metainfo
    assert meta['prev_tokens'] == ['synthetic-1@t-1']
    assert np.array_equal(meta['prev2curr'], np.eye(4)[None])
    for key in ('cam2img', 'lidar2cam', 'img_aug_matrix', 'lidar2img'):
        assert meta[f'prev_{key}'].shape == (1, 6, 4, 4)
        assert np.array_equal(meta[f'prev_{key}'][0], meta[key])
    (prev, ) = meta['prev_points']
    assert prev.shape == (20, 5) and (prev[:, 4] == 0).all()
    assert '2 frames' in description
