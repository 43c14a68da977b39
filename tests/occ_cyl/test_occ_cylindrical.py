"""Tests of the OccCylindrical detector under the mmengine contract."""
import copy

import pytest
import torch
from mmdet3d.registry import MODELS
from mmdet3d.structures import Det3DDataSample
from mmdet3d.utils import register_all_modules

import projects.occ_cyl  # noqa: F401
from projects.occ_common.synthetic.occ_inputs import make_occ_batch

register_all_modules(init_default_scope=False)

PC_RANGE = [-8.0, -8.0, -2.0, 8.0, 8.0, 2.0]
VOXEL = [2.0, 2.0, 1.0]  # an (8, 8, 4) grid
DEPTH_BOUND = [1.0, 13.0, 2.0]  # 6 bins at 1, 3, ..., 11 m
NUM_BINS = 6
CFG = dict(
    type='OccCylindrical',
    data_preprocessor=dict(type='mmdet3d.Det3DDataPreprocessor'),
    point_cloud_range=PC_RANGE,
    voxel_size=VOXEL,
    num_classes=4,
    cylinder=dict(shape=[8, 16, 4]),
    depth_bound=DEPTH_BOUND,
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
        camera_param_dims=22,
        num_res_blocks=1,
        aspp_dilations=(1, 2)),
    point_branch=dict(
        type='LidarPointBranch', in_channels=5, img_channels=6,
        geo_channels=(8, ), out_channels=(8, )),
    tpv_fusion=dict(
        type='TPVPolarFusion', cam_channels=6, lidar_channels=8,
        plane_channels=8, num_groups=2),
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
        type='CylindricalOccHead', in_channels=8, num_scales=2,
        hidden_channels=8,
        loss_occ=dict(
            type='MultiScaleOccupancyLoss',
            losses=[
                dict(type='OccFocalLoss'),
                dict(type='OccLovaszLoss'),
                dict(type='SceneClassAffinityLoss', mode='geo'),
                dict(type='SceneClassAffinityLoss', mode='sem')
            ])),
    loss_depth=dict(type='DepthBCELoss', downsample=16, loss_weight=3.0))


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


def test_one_owner_of_the_shared_values():
    """The detector builds one cylinder covering (-8, 8)^2 (radius
    8 sqrt(2) + 0.01 m) and hands that same object to the fusion and the
    head; DepthNet predicts the 6 bins of depth_bound with 4 * 6 = 24
    position channels (r, sin, cos, z), and the loss terms get empty_index
    2 / ignore 7."""
    model = _build(empty_index=2, ignore_index=7)
    assert model.tpv_fusion.cylinder is model.cylinder
    assert model.occ_head.cylinder is model.cylinder
    assert model.cylinder.shape == (8, 16, 4)
    assert model.cylinder.cyl_range[3] == pytest.approx(8 * 2**0.5 + 0.01)
    assert model.depth_net.num_depth_bins == NUM_BINS
    assert model.depth_net.position_channels == 4 * NUM_BINS
    assert model.loss_depth.depth_bound == tuple(DEPTH_BOUND)
    assert model.occ_head.scale_shapes == [(8, 8, 4), (4, 4, 2)]
    sem = model.occ_head.loss_occ.losses[3]
    assert (sem.empty_index, sem.ignore_index) == (2, 7)


def test_inscribed_clamping_cylinder_trains():
    """PointOcc's cylinder: radius 8 m (the inscribed circle of
    (-8, 8)^2), points and output voxels beyond it clamped into the
    outer ring. The head accepts it although the corners (11.3 m) lie
    outside, and every parameter still gets a gradient."""
    model = _build(cylinder=dict(radius='inscribed', clamp=True))
    assert model.cylinder.cyl_range[3] == 8.0 and model.cylinder.clamp
    data = _data(model, True, batch_size=1, num_points=(30, ))
    sum(model(**data, mode='loss').values()).backward()
    no_grad = [n for n, p in model.named_parameters()
               if p.requires_grad and p.grad is None]
    assert no_grad == []


def test_cylinder_the_plane_encoder_would_pad_is_refused():
    """Issue 11, item 6, at construction: the test Swin's coarsest level
    has stride 2, so a 15-cell azimuth (levels 15 and 8 cells, the second
    covering 16) is refused, naming the plane and the level."""
    with pytest.raises(ValueError, match=r'\(R, Theta\) plane \(8, 15\).*'
                       r'level 1.*cover 16 cells'):
        _build(cylinder=dict(shape=[8, 15, 4]), tpv_fusion=dict(num_groups=1))
    with pytest.raises(ValueError, match='cylinder needs shape'):
        _build(cylinder=dict(shape=[8, 16, 4], size=3))


def test_bad_inputs_raise():
    """Conflicting depth bins or labels, missing inputs, metainfo and GT
    are named."""
    with pytest.raises(ValueError, match='num_depth_bins=5'):
        _build(depth_net=dict(num_depth_bins=5))
    with pytest.raises(ValueError, match='depth_bound'):
        _build(loss_depth=dict(depth_bound=[1.0, 13.0, 1.0]))
    with pytest.raises(ValueError, match='empty_index'):
        _build(occ_head=dict(
            loss_occ=dict(CFG['occ_head']['loss_occ'], empty_index=1)))
    with pytest.raises(ValueError, match='position_channels'):
        _build(depth_net=dict(position_channels=5))
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


#: A semantic head of 3 classes on the DepthNet and its loss (not in the
#: paper; the seg2d synthetic config).
SEG = dict(
    depth_net=dict(seg_channels=3),
    loss_seg=dict(type='mmdet.CrossEntropyLoss', ignore_index=255,
                  avg_non_ignore=True, loss_weight=0.5))


def _seg_data(model):
    """One sample whose 2-D labels are 1 where a return is nearer than 6
    m, 2 beyond, 255 where there is none."""
    data = _data(model, True, num_points=(200, ))
    for sample in data['data_samples']:
        depth = sample.gt_depth
        sample.gt_seg_2d = torch.where(
            depth > 0, torch.where(depth <= 6, 1, 2), 255).to(torch.uint8)
    return data


def test_semantic_loss_reaches_the_seg_head_with_its_weight():
    """loss_seg is 0.5 x the cross-entropy of the DepthNet's seg_logits
    against the nearest labelled return of each 16x16 cell (computed here
    from the same tensors); its gradient reaches the seg head and the
    image encoder, and weight 1.0 doubles both loss and gradient."""
    from projects.occ_common.geometry import downsample_seg_labels
    grads, values = {}, {}
    for weight in (0.5, 1.0):
        model = _build(depth_net=SEG['depth_net'],
                       loss_seg=dict(SEG['loss_seg'], loss_weight=weight))
        data = _seg_data(model)
        losses = model(**data, mode='loss')
        assert 'loss_seg' in losses and 'loss_depth' in losses
        out = model.extract_feat(data['inputs'], data['data_samples'])
        gt_depth = model.gt_depth(data['data_samples'], torch.device('cpu'),
                                  data['inputs']['imgs'].shape[-2:])
        gt_seg = torch.stack([s.gt_seg_2d for s in data['data_samples']
                              ]).flatten(0, 1)
        target = downsample_seg_labels(gt_seg, gt_depth, 16)
        logits = out['seg_logits'].permute(0, 2, 3, 1).reshape(-1, 3)
        expected = weight * torch.nn.functional.cross_entropy(
            logits, target.reshape(-1), ignore_index=255)
        assert (target != 255).sum() > 0
        torch.testing.assert_close(losses['loss_seg'], expected)
        model.zero_grad()
        losses['loss_seg'].backward()
        head = model.depth_net.seg_head[-1].weight.grad
        encoder = [p.grad for p in model.img_encoder.parameters()
                   if p.grad is not None]
        assert head.abs().sum() > 0 and encoder
        assert sum(g.abs().sum() for g in encoder) > 0
        grads[weight], values[weight] = head.clone(), losses['loss_seg']
    torch.testing.assert_close(values[1.0], 2 * values[0.5])
    torch.testing.assert_close(grads[1.0], 2 * grads[0.5])


def test_seg_head_without_its_loss_gets_no_gradient_and_loss_needs_head():
    """Without loss_seg the seg head takes no part in the loss; loss_seg
    without a seg head is refused when the model is built."""
    model = _build(depth_net=SEG['depth_net'])
    data = _seg_data(model)
    losses = model(**data, mode='loss')
    assert 'loss_seg' not in losses
    sum(losses.values()).backward()
    assert model.depth_net.seg_head[-1].weight.grad is None
    with pytest.raises(ValueError, match='loss_seg needs a DepthNet with '
                       'seg_channels > 0'):
        _build(loss_seg=SEG['loss_seg'])


def test_seg_targets_follow_the_padded_depth_maps():
    """The paper config's 900-row images are padded to 928 rows, and the
    depth maps with them; the 2-D labels are padded the same way with the
    ignore label. Here 32 rows padded to 48 at stride 16: the first two
    target rows equal those of the unpadded maps, the padded third row is
    all 255 (no return, no label)."""
    model = _build(**SEG)
    samples = _seg_data(model)['data_samples']
    cpu = torch.device('cpu')
    plain = model.seg_targets(samples, model.gt_depth(samples, cpu), 16)
    padded = model.seg_targets(samples, model.gt_depth(samples, cpu,
                                                       (48, 64)), 16)
    assert tuple(plain.shape) == (2, 2, 4)
    assert tuple(padded.shape) == (2, 3, 4)
    assert torch.equal(padded[:, :2], plain)
    assert (padded[:, 2] == 255).all()
    assert (plain != 255).any()
