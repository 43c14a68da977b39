"""Tests of the OccCylindrical detector under the mmengine contract."""
import copy
import math

import pytest
import torch
from mmdet3d.registry import MODELS
from mmdet3d.structures import Det3DDataSample
from mmdet3d.utils import register_all_modules

import projects.occ_cyl  # noqa: F401
from projects.occ_common.testing.occ_inputs import make_occ_batch

register_all_modules(init_default_scope=False)

PC_RANGE = [-8.0, -8.0, -2.0, 8.0, 8.0, 2.0]
CYL_RANGE = [0.0, -math.pi, -2.0, 8 * math.sqrt(2) + 0.01, math.pi, 2.0]
GRID = [8, 16, 4]
DEPTH_BOUND = [1.0, 13.0, 2.0]  # 6 bins at 1, 3, ..., 11 m
NUM_BINS = 6
CFG = dict(
    type='OccCylindrical',
    data_preprocessor=dict(type='mmdet3d.Det3DDataPreprocessor'),
    img_encoder=dict(
        type='MultiViewImageEncoder',
        backbone=dict(
            type='mmdet.ResNet', depth=18, base_channels=4,
            out_indices=(1, 2, 3)),
        neck=dict(
            type='mmdet.FPN', in_channels=[8, 16, 32], out_channels=8,
            num_outs=3),
        neck_channels=8,
        num_levels=3,
        out_channels=8),
    depth_net=dict(
        type='DepthNet',
        in_channels=8,
        mid_channels=8,
        context_channels=6,
        num_depth_bins=NUM_BINS,
        position_channels=3 * NUM_BINS,
        camera_param_dims=22,
        num_res_blocks=1,
        aspp_dilations=(1, 2)),
    point_branch=dict(
        type='LidarPointBranch', in_channels=5, img_channels=6,
        geo_channels=(8, ), out_channels=(8, )),
    tpv_fusion=dict(
        type='TPVPolarFusion', grid_shape=GRID, cyl_range=CYL_RANGE,
        cam_channels=6, lidar_channels=8, plane_channels=8, num_groups=2),
    tpv_encoder=dict(
        type='TPVPlaneEncoder',
        backbone=dict(
            type='mmdet.SwinTransformer', in_channels=8, embed_dims=8,
            depths=(1, 1), num_heads=(1, 1), window_size=2, patch_size=1,
            strides=(1, 2), out_indices=(0, 1), pretrain_img_size=8),
        neck=dict(
            type='mmdet.FPN', in_channels=[8, 16], out_channels=8,
            num_outs=2)),
    occ_head=dict(
        type='CylindricalOccHead', in_channels=8, grid_shape=GRID,
        cyl_range=CYL_RANGE, pc_range=PC_RANGE,
        scale_shapes=[(8, 8, 4), (4, 4, 2)], hidden_channels=8,
        num_classes=4,
        loss_occ=dict(
            type='MultiScaleOccupancyLoss', num_scales=2,
            losses=[
                dict(type='OccFocalLoss'),
                dict(type='OccLovaszLoss'),
                dict(type='SceneClassAffinityLoss', mode='geo'),
                dict(type='SceneClassAffinityLoss', mode='sem')
            ])),
    depth_bound=DEPTH_BOUND,
    loss_depth=dict(
        type='DepthBCELoss', depth_bound=DEPTH_BOUND, downsample=16,
        loss_weight=3.0))


def _build(**overrides):
    cfg = copy.deepcopy(CFG)
    for key, value in overrides.items():
        if isinstance(value, dict) and key in cfg:
            cfg[key].update(value)
        else:
            cfg[key] = value
    torch.manual_seed(0)
    return MODELS.build(cfg)


def _data(model, training, **kwargs):
    inputs, samples = make_occ_batch(**kwargs)
    data = dict(
        inputs=dict(img=list(inputs['imgs']), points=inputs['points']),
        data_samples=samples)
    return model.data_preprocessor(data, training)


def test_loss_terms_and_backward_with_an_empty_cloud():
    """Eq. 19: four occupancy terms per scale (weighted 1, 1/2) plus
    loss_depth; sample 1 has no LiDAR point at all. Every parameter that
    takes part receives a gradient."""
    model = _build()
    data = _data(model, True, batch_size=2, num_points=(40, 0))
    losses = model(**data, mode='loss')
    expected = {f'{n}_s{s}' for n in ('loss_focal', 'loss_lovasz',
                                      'loss_geo_scal', 'loss_sem_scal')
                for s in (0, 1)} | {'loss_depth'}
    assert set(losses) == expected
    assert all(torch.isfinite(v) for v in losses.values())
    assert losses['loss_depth'] > 0
    sum(losses.values()).backward()
    no_grad = [n for n, p in model.named_parameters()
               if p.requires_grad and p.grad is None]
    assert no_grad == []


def test_one_lidar_point_trains():
    """A batch whose only LiDAR point survived the filters: BatchNorm1d of
    the point branch raised ("Expected more than 1 value per channel")."""
    model = _build()
    model.train()
    data = _data(model, True, batch_size=1, num_points=(1, ))
    assert data['inputs']['points'][0].shape[0] == 1
    losses = model(**data, mode='loss')
    assert all(torch.isfinite(v) for v in losses.values())
    sum(losses.values()).backward()
    assert model.point_branch.geo_mlp[0].weight.grad is not None


def test_predict_returns_finest_labels_and_keeps_gt():
    """predict sets pred_occ (8, 8, 4) int64 in [0, 4) and keeps gt_occ and
    mask_camera for the metric; tensor mode returns both scales' logits."""
    model = _build().eval()
    data = _data(model, False, batch_size=1, num_points=(30, ))
    with torch.no_grad():
        results = model(**data, mode='predict')
        logits = model(**data, mode='tensor')
    sample = results[0]
    assert sample.pred_occ.shape == (8, 8, 4)
    assert sample.pred_occ.dtype == torch.long
    assert int(sample.pred_occ.max()) < 4
    assert torch.equal(sample.pred_occ, logits[0][0].argmax(0))
    assert [tuple(x.shape) for x in logits] == [(1, 4, 8, 8, 4),
                                                (1, 4, 4, 4, 2)]
    as_dict = sample.to_dict()
    assert {'pred_occ', 'gt_occ', 'mask_camera'} <= set(as_dict)


def test_ablations_of_table_v():
    """No depth supervision drops loss_depth; no depth feature / no position
    embedding build DepthNet without those branches and still train."""
    model = _build(loss_depth=None,
                   depth_net=dict(with_depth_feature=False,
                                  position_channels=0))
    assert not hasattr(model.depth_net, 'depth_embed')
    assert not hasattr(model.depth_net, 'position_embed')
    data = _data(model, True, batch_size=1, num_points=(20, ))
    losses = model(**data, mode='loss')
    assert 'loss_depth' not in losses
    sum(losses.values()).backward()


def test_loss_mask_key_ignores_voxels_outside_the_camera_mask():
    """With loss_mask_key='mask_camera' and an all-False mask every voxel
    becomes ignored: the focal terms are exactly 0."""
    model = _build(loss_mask_key='mask_camera', loss_depth=None)
    data = _data(model, True, batch_size=1, num_points=(20, ))
    data['data_samples'][0].mask_camera[:] = False
    losses = model(**data, mode='loss')
    assert losses['loss_focal_s0'].item() == 0.0
    assert losses['loss_focal_s1'].item() == 0.0


def test_fused_and_naive_lift_give_the_same_model_output():
    """Switching the lift-pool path changes nothing in the logits."""
    fused = _build().eval()
    naive = _build(tpv_fusion=dict(fused_lift=False)).eval()
    naive.load_state_dict(fused.state_dict())
    data = _data(fused, False, batch_size=1, num_points=(25, ))
    with torch.no_grad():
        a = fused(**data, mode='tensor')
        b = naive(**data, mode='tensor')
    assert all(torch.equal(x, y) for x, y in zip(a, b))


def test_bad_inputs_raise():
    """Mismatched depth bins, missing inputs, metainfo and GT are named."""
    with pytest.raises(ValueError, match='6 bins'):
        _build(depth_net=dict(num_depth_bins=5, position_channels=15))
    model = _build()
    data = _data(model, True, batch_size=1, num_points=(20, ))
    with pytest.raises(ValueError, match='"points"'):
        model.loss(dict(imgs=data['inputs']['imgs']), data['data_samples'])
    del data['data_samples'][0].gt_occ
    with pytest.raises(ValueError, match="sample 0 has no 'gt_occ'"):
        model.loss(data['inputs'], data['data_samples'])
    data = _data(model, True, batch_size=1, num_points=(20, ))
    meta = {
        k: v
        for k, v in data['data_samples'][0].metainfo.items()
        if k not in ('lidar2img', 'cam2img')
    }
    with pytest.raises(ValueError, match="'cam2img'"):
        model.predict(data['inputs'], [Det3DDataSample(metainfo=meta)])
