"""The OccCylindrical configs are deltas that state each fact once.

test_all_configs.py builds every config and compares its model with the
committed fingerprint; test_tiny_configs.py trains the tiny ones.
"""
import glob
import math
import os.path as osp

import pytest
import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.optim import build_optim_wrapper
from mmengine.registry import init_default_scope

from projects.occ_common.testing.config_delta import (coupled_value_mismatches,
                                                      model_delta)

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG_DIR = osp.join(ROOT, 'configs', 'occ_cyl')
MODEL_BASE = osp.join(CONFIG_DIR, '_base_', 'occcyl_r50-swins.py')
MAIN = sorted(glob.glob(osp.join(CONFIG_DIR, '*.py')))
ABLATIONS = sorted(glob.glob(osp.join(CONFIG_DIR, 'ablations', '*.py')))
PAPER = osp.join(CONFIG_DIR, 'occcyl_r50-swins_3xb1-24e_surroundocc-nus.py')
OCC3D = osp.join(CONFIG_DIR, 'occcyl_r50-swins_3xb1-24e_occ3d-nus.py')
LITE = osp.join(CONFIG_DIR,
                'occcyl-lite_r50-swint_3xb1-24e_surroundocc-nus.py')
NOMASK = osp.join(CONFIG_DIR,
                  'occcyl_r50-swins_3xb1-24e_occ3d-nus-nomask.py')
TINY = osp.join(CONFIG_DIR, 'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')
SMALL = osp.join(CONFIG_DIR,
                 'occcyl_small_1xb1-12e_surroundocc-nus-synthetic.py')
SMALL_OCC3D = osp.join(
    CONFIG_DIR, 'occcyl_small_1xb1-12e_occ3d-nus-nomask-synthetic.py')
SEG2D = osp.join(CONFIG_DIR,
                 'occcyl-seg2d_small_1xb1-12e_surroundocc-nus-synthetic.py')
QUAD = SMALL.replace('surroundocc-nus', 'surroundocc-quad')

#: What each config changes in the model of the config it builds on.
COUPLED = {'point_cloud_range', 'voxel_size', 'num_classes', 'empty_index'}
DELTAS = {
    # Dataset configs on the model base: the coupled values only.
    PAPER: (MODEL_BASE, COUPLED),
    OCC3D: (MODEL_BASE, COUPLED | {'loss_mask_key'}),
    # RayIoU (issue 49): the Occ3D config trained on whole grids.
    NOMASK: (OCC3D, {'loss_mask_key'}),
    # The lighter model: the slimmer widths and Swin-T's ImageNet weights,
    # nothing else.
    LITE: (PAPER, {
        'pretrained.tpv_backbone.checkpoint',
        'img_encoder.backbone.out_indices', 'img_encoder.neck.in_channels',
        'img_encoder.neck.num_outs', 'img_encoder.num_levels',
        'img_encoder.out_channels', 'depth_net.in_channels',
        'depth_net.mid_channels', 'tpv_encoder.backbone.depths',
        'tpv_encoder.backbone.drop_path_rate'
    }),
    # The learning benchmark's small model: the tiny one with a finer
    # cylinder and depth bins, twice the widths, a GroupNorm image branch
    # and a TPV encoder whose finest level keeps the cylinder's cells.
    SMALL: (TINY, {
        'cylinder.shape', 'depth_bound', 'depth_net.context_channels',
        'depth_net.in_channels', 'depth_net.mid_channels',
        'depth_net.norm_cfg.type', 'depth_net.norm_cfg.num_groups',
        'img_encoder.backbone.norm_cfg.type',
        'img_encoder.backbone.norm_cfg.num_groups',
        'img_encoder.norm_cfg.type', 'img_encoder.norm_cfg.num_groups',
        'img_encoder.backbone.base_channels', 'img_encoder.neck.in_channels',
        'img_encoder.neck.out_channels', 'img_encoder.neck_channels',
        'img_encoder.out_channels', 'occ_head.hidden_channels',
        'occ_head.in_channels', 'point_branch.geo_channels',
        'point_branch.img_channels', 'point_branch.out_channels',
        'tpv_encoder.backbone.embed_dims', 'tpv_encoder.backbone.in_channels',
        'tpv_encoder.backbone.num_heads', 'tpv_encoder.backbone.patch_size',
        'tpv_encoder.backbone.strides', 'tpv_encoder.neck.in_channels',
        'tpv_encoder.neck.out_channels', 'tpv_fusion.cam_channels',
        'tpv_fusion.lidar_channels', 'tpv_fusion.plane_channels'
    }),
    # The learning benchmark's RayIoU row (issue 49): the small model on
    # Occ3D's grid and classes, trained on whole grids as SMALL is.
    SMALL_OCC3D: (SMALL, COUPLED),
    # Not in the paper: the small model with a 2-D semantic head and loss.
    SEG2D: (SMALL, {
        'depth_net.seg_channels', 'loss_seg.type', 'loss_seg.ignore_index',
        'loss_seg.avg_non_ignore', 'loss_seg.loss_weight'
    }),
    # The four-camera rig without LiDAR ring index: data only.
    QUAD: (SMALL, set()),
    # The dataset base's geometric augmentation: the pipeline only.
    'occcyl-geoaug': (PAPER, set()),
    # Table V (3), VI (2) and VII (3): one knob each.
    'occcyl-nodepthsup': (PAPER, {'loss_depth'}),
    'occcyl-nodepthfeat': (PAPER, {'depth_net.with_depth_feature'}),
    'occcyl-nopos': (PAPER, {'depth_net.position_channels'}),
    'occcyl-d2m': (PAPER, {'depth_bound'}),
    'occcyl-d10m': (PAPER, {'depth_bound'}),
    'occcyl-m1': (PAPER, {'tpv_fusion.num_groups'}),
    'occcyl-m2': (PAPER, {'tpv_fusion.num_groups'}),
    'occcyl-m4': (PAPER, {'tpv_fusion.num_groups'}),
}


def _name(path):
    return osp.basename(path).split('_')[0] if '/ablations/' in path else path


def test_config_inventory():
    """The paper's config, its Occ3D variant (also without the camera
    mask, for RayIoU), the lighter model, the tiny
    and small synthetic configs (the small one also with a 2-D semantic
    target, on Occ3D without the mask, and on the four-camera rig), the
    deltas of Tables V (3 files), VI (2) and VII (3) and the
    geometric-augmentation option."""
    assert set(MAIN) == {
        PAPER, OCC3D, NOMASK, LITE, TINY, SMALL, SMALL_OCC3D, SEG2D, QUAD
    }
    assert ({_name(p) for p in ABLATIONS}
            | {PAPER, OCC3D, NOMASK, LITE, SMALL, SMALL_OCC3D, SEG2D, QUAD}
            == set(DELTAS))


@pytest.mark.parametrize(
    'path',
    [PAPER, OCC3D, NOMASK, LITE, SMALL, SMALL_OCC3D, SEG2D, QUAD] +
    ABLATIONS,
    ids=lambda p: osp.basename(p)[:-3])
def test_each_delta_changes_only_its_documented_keys(path):
    """Compared with the config it builds on, a config changes exactly the
    model keys listed in DELTAS."""
    parent, keys = DELTAS[_name(path)]
    assert model_delta(parent, path) == keys


@pytest.mark.parametrize('path', MAIN, ids=lambda p: osp.basename(p)[:-3])
def test_coupled_values_come_from_the_dataset_base(path):
    """The model's grid, classes and empty label are the dataset base's
    (Occ3D: 'free' = 17 and the camera-mask loss, as the metric), the
    config needs both packages, and the images are the paper's size."""
    cfg = Config.fromfile(path)
    assert coupled_value_mismatches(cfg, 'occ_cyl') == []
    aug = [t for t in cfg.train_pipeline if t.type == 'MultiViewImageAug']
    assert aug[0].final_size == cfg.img_size


def test_small_occ3d_config_has_occ3d_data_and_metric():
    """The small config switched to Occ3D loads, transforms and scores the
    labels as the paper's Occ3D config does (the same label, frame and
    crop steps in the same order, the same dataset keys, the same voxel
    metric), and adds RayIoU. Its augmentations stay the small config's."""
    small, paper = Config.fromfile(SMALL_OCC3D), Config.fromfile(OCC3D)
    task_steps = ('LoadOccupancyGT', 'PointsToEgoFrame', 'PointsRangeFilter')

    def label_steps(pipeline):
        return [dict(t) for t in pipeline if t['type'] in task_steps]

    for split in ('train', 'test'):
        steps = label_steps(small[f'{split}_pipeline'])
        assert [t['type'] for t in steps] == list(task_steps)
        assert steps == label_steps(paper[f'{split}_pipeline']), split
    for key in ('occ_format', 'metainfo'):
        assert (small.train_dataloader.dataset[key] ==
                paper.train_dataloader.dataset[key])
    voxel_metric, ray_metric = small.val_evaluator
    assert dict(voxel_metric) == dict(paper.val_evaluator)
    assert ray_metric.type == 'OccRayIoUMetric'


def _augmentations(path):
    """The augmentation steps of a config's training pipeline, in order."""
    return [
        dict(t) for t in Config.fromfile(path).train_pipeline
        if t['type'] in ('MultiViewImageAug', 'MultiViewPhotoMetric',
                         'OccBEVAug')
    ]


def test_paper_configs_train_with_the_lineage_recipe():
    """Issue 47: SurroundOcc's and OCCFusion's photometric distortion right
    after the images, no geometric change (the training images get the
    test pipeline's geometry: scale 1, crop at the midpoints 0.5 / 1.0, no
    rotation or flip; no BEV flip); the image backbone at a tenth of the
    rate, DCNv2 in ResNet stages 3 and 4, ImageNet Swin-S weights. The
    geoaug option restores the dataset base's ranges and drops the
    distortion. The tiny config, trained from scratch, keeps the full rate
    and no DCN (ResNet-18)."""
    for path in (PAPER, OCC3D, NOMASK):
        image, photometric, bev = _augmentations(path)
        assert image == dict(
            type='MultiViewImageAug', final_size=(900, 1600),
            resize_range=(1.0, 1.0), crop_x_range=(0.5, 0.5),
            crop_y_range=(1.0, 1.0), flip_prob=0.0, rot_range=(0.0, 0.0))
        assert photometric == dict(type='MultiViewPhotoMetric')
        assert bev == dict(type='OccBEVAug', flip_x_prob=0.0,
                           flip_y_prob=0.0)
        cfg = Config.fromfile(path)
        assert cfg.optim_wrapper.paramwise_cfg.custom_keys == {
            'img_encoder.backbone': dict(lr_mult=0.1)}
        backbone = cfg.model.img_encoder.backbone
        assert backbone.dcn.type == 'Float32DCNv2'
        assert backbone.stage_with_dcn == (False, False, True, True)
        assert cfg.model.pretrained.tpv_backbone.checkpoint.endswith(
            'swin_small_patch4_window7_224.pth')
    geo = osp.join(CONFIG_DIR, 'ablations',
                   'occcyl-geoaug_r50-swins_3xb1-24e_surroundocc-nus.py')
    image, bev = _augmentations(geo)
    assert (image['resize_range'], image['flip_prob'],
            image['rot_range']) == ((0.94, 1.06), 0.5, (-5.4, 5.4))
    assert (bev['flip_x_prob'], bev['flip_y_prob']) == (0.5, 0.5)
    tiny = Config.fromfile(TINY)
    assert tiny.optim_wrapper.paramwise_cfg.custom_keys == {
        'img_encoder.backbone': dict(lr_mult=1.0)}
    assert tiny.model.img_encoder.backbone.dcn is None


def test_image_backbone_learns_at_a_tenth_of_the_rate():
    """The optimiser mmengine builds for the paper config gives the image
    backbone's parameters 5e-5 x 0.1 = 5e-6 and everything else 5e-5."""
    cfg = Config.fromfile(PAPER)
    init_default_scope(cfg.default_scope)
    model = MODELS.build(cfg.model)
    optimizer = build_optim_wrapper(model, cfg.optim_wrapper).optimizer
    rate = {id(p): group['lr'] for group in optimizer.param_groups
            for p in group['params']}
    backbone = {id(p) for p in model.img_encoder.backbone.parameters()}
    trained = [p for p in model.parameters() if p.requires_grad]
    assert {rate[id(p)] for p in trained if id(p) in backbone} == {5e-6}
    assert {rate[id(p)] for p in trained if id(p) not in backbone} == {5e-5}


def test_ablation_knobs():
    """Table VI: (1, 51, d) gives 25 bins at d = 2 and 5 at d = 10; Table
    VII: M = 1, 2, 4."""
    for path in ABLATIONS:
        name, model = _name(path), Config.fromfile(path).model
        if name.startswith('occcyl-d'):
            step = float(name[len('occcyl-d'):-1])
            assert model.depth_bound == [1.0, 51.0, step]
        if name.startswith('occcyl-m'):
            assert model.tpv_fusion.num_groups == int(name[-1])


def test_paper_silent_choices_of_issue_14():
    """Every OccCylindrical config that supervises depth trains it onto the
    nearest bin point, and every one normalises the raw point attributes
    (the reasons and numbers: the base config's comments)."""
    paths = sorted(glob.glob(osp.join(CONFIG_DIR, '*.py')) + ABLATIONS)
    for path in paths:
        model = Config.fromfile(path).model
        assert model.point_branch.input_norm is True, path
        if model.get('loss_depth') is not None:
            assert model.loss_depth.nearest_bin is True, path


def test_paper_model_parameter_count(capsys):
    """Issue 11, item 5. Table IV: 111.62 M parameters. The paper config
    lands within 3 %: ResNet-50 23,508,032 (torchvision's 25,557,032 minus
    the 2048 x 1000 + 1000 fc) plus the DCNv2 offset convs of stages 3 and
    4 (one 3 x 3 conv to 27 channels with bias in each block: 6 x (256 x 9
    x 27 + 27) + 3 x (512 x 9 x 27 + 27) = 373,410 + 373,329 = 746,739),
    Swin-S 48.88 M (its 49.6 M ImageNet model without the 0.77 M
    classifier, with a 128-channel 2 x 2 patch embedding), BEVDepth's
    512-wide DepthNet 28.4 M. The count by module is printed for the
    report."""
    cfg = Config.fromfile(PAPER)
    init_default_scope(cfg.default_scope)
    model = MODELS.build(cfg.model)
    backbone = sum(p.numel() for p in model.img_encoder.backbone.parameters())
    dcn_offsets = 6 * (256 * 9 * 27 + 27) + 3 * (512 * 9 * 27 + 27)
    assert dcn_offsets == 746_739
    assert backbone == 25_557_032 - (2048 * 1000 + 1000) + dcn_offsets
    parts = {
        name: sum(p.numel() for p in child.parameters())
        for name, child in model.named_children()
    }
    total = sum(p.numel() for p in model.parameters())
    assert total == sum(parts.values())
    assert abs(total / 111.62e6 - 1) <= 0.03
    with capsys.disabled():
        error = 100 * (total / 111.62e6 - 1)
        print(f'\nOccCylindrical paper config: {total / 1e6:.2f} M '
              f'parameters (paper: 111.62 M, {error:+.1f} %); ' +
              ', '.join(f'{k} {v / 1e6:.2f} M'
                        for k, v in parts.items() if v))


def test_image_neck_takes_stages_0_to_3():
    """Issue 11, item 4 (Sec. IV.A: stages 0, 1, 2 and 3 feed the FPN). A
    64 x 64 image reaches the FPN as four maps of 256, 512, 1024 and 2048
    channels at strides 4, 8, 16, 32 (16, 8, 4, 2 cells), and all four FPN
    levels are fused into V (512 channels at 1/16: 4 x 4)."""
    cfg = Config.fromfile(PAPER)
    init_default_scope(cfg.default_scope)
    encoder = MODELS.build(cfg.model.img_encoder).eval()
    seen = []
    encoder.neck.register_forward_pre_hook(
        lambda module, args: seen.extend(tuple(x.shape) for x in args[0]))
    with torch.no_grad():
        v = encoder(torch.zeros(1, 1, 3, 64, 64))
    assert seen == [(1, 256, 16, 16), (1, 512, 8, 8), (1, 1024, 4, 4),
                    (1, 2048, 2, 2)]
    assert encoder.num_levels == 4
    assert tuple(v.shape) == (1, 512, 4, 4)


@pytest.mark.parametrize('path', [PAPER, OCC3D],
                         ids=lambda p: osp.basename(p)[:-3])
def test_paper_configs_load_the_key_frame_and_9_sweeps(path):
    """Issue 11, item 8: "10 LiDAR sweeps" as the authors' OccFusion code
    loads them, the key frame and 9 sweeps (sweeps_num=9), in training and
    testing."""
    cfg = Config.fromfile(path)
    assert cfg.sweeps_num == 9
    for pipeline in (cfg.train_pipeline, cfg.test_pipeline,
                     cfg.train_dataloader.dataset.pipeline,
                     cfg.val_dataloader.dataset.pipeline):
        sweeps = [t for t in pipeline
                  if t.type == 'LoadOccPointsFromMultiSweeps']
        assert [t.sweeps_num for t in sweeps] == [9]


def test_paper_cylinder_is_pointocc_with_swin_friendly_azimuth():
    """PointOcc's cylinder, r in [0, 50] m, theta in [-pi, pi], z in
    [-5, 3] m, outside points clamped; 480 x 368 x 32 cells (368 = 16 x 23
    so that the coarsest Swin level, stride 16, covers the azimuth exactly)
    and M = 8 divides every side."""
    cfg = Config.fromfile(PAPER)
    init_default_scope(cfg.default_scope)
    model = MODELS.build(cfg.model)
    cyl = model.cylinder
    assert cyl.shape == (480, 368, 32) and cyl.clamp
    assert cyl.cyl_range == pytest.approx(
        (0.0, -math.pi, -5.0, 50.0, math.pi, 3.0))
    assert model.tpv_encoder.level_strides == (2, 4, 8, 16)
    assert all(side % 16 == 0 and side % 8 == 0 for side in cyl.shape)


def _train_step(module, inputs, seed):
    """Outputs, input and parameter gradients and buffers (three lists)
    after one forward + backward of a module in training mode."""
    torch.manual_seed(seed)
    inputs = inputs.clone().requires_grad_()
    module.train()
    outs = module(inputs)
    outs = [outs] if isinstance(outs, torch.Tensor) else outs
    loss = sum((o * torch.linspace(-1, 1, o.numel()).view(o.shape)).sum()
               for o in outs)
    # backward(), not autograd.grad: mmdet's reentrant checkpoints take
    # only the former, as the runner calls it.
    loss.backward()
    grads = [inputs.grad] + [
        p.grad for p in module.parameters() if p.requires_grad
    ]
    assert all(g is not None for g in grads)
    return list(outs), grads, [b.clone() for b in module.buffers()]


@pytest.mark.parametrize(
    'part', ['img_encoder.backbone', 'img_encoder', 'tpv_encoder.backbone'])
def test_paper_backbone_checkpointing_is_exact(part):
    """Issue 18: the paper config recomputes the ResNet's bottlenecks, the
    image FPN and the Swin's blocks in the backward (``with_cp``) to fit
    one training iteration in memory. That is exact: the ResNet's
    BatchNorms run with frozen statistics (``norm_eval``), so the
    recomputation updates no running statistic twice, the FPN has none,
    and the Swin's drop-path masks are redrawn from the saved random
    state. In float64 on 64 x 64 images / a 128-channel 32 x 32 plane,
    outputs and buffers are bitwise those without it, gradients (input and
    every trainable parameter) equal up to the order of summation (the
    ResNet's residual sums; measured <= 5e-16 relative, bitwise for the
    Swin)."""
    cfg = Config.fromfile(PAPER)
    init_default_scope(cfg.default_scope)
    backbone_cfg = cfg.model
    for key in part.split('.'):
        backbone_cfg = backbone_cfg[key]
    assert backbone_cfg.with_cp
    channels = backbone_cfg.get('in_channels', 3)
    size = 64 if channels == 3 else 32
    # The encoder takes (B, N, 3, H, W): two views.
    shape = (1, 2, 3) if part == 'img_encoder' else (1, channels)
    inputs = torch.randn(*shape, size, size, dtype=torch.float64)
    results = []
    for with_cp in (False, True):
        torch.manual_seed(0)
        module = MODELS.build(dict(backbone_cfg, with_cp=with_cp)).double()
        results.append(_train_step(module, inputs, seed=1))
    (plain_out, plain_grads, plain_bufs), (cp_out, cp_grads,
                                           cp_bufs) = results
    assert all(torch.equal(a, b) for a, b in zip(plain_out, cp_out))
    assert all(torch.equal(a, b) for a, b in zip(plain_bufs, cp_bufs))
    assert len(plain_grads) == len(cp_grads)
    for a, b in zip(plain_grads, cp_grads):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-14)


def test_paper_head_checkpoints_its_scales():
    """The head recomputes its plane samples in the backward too
    (exactness: tests/occ_cyl/test_cylindrical_occ_head.py)."""
    assert Config.fromfile(PAPER).model.occ_head.with_cp
