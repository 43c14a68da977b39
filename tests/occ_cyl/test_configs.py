"""Every OccCylindrical config builds; the tiny one trains and tests."""
import glob
import math
import os.path as osp
import re

import pytest
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope

from projects.occ_common.testing.tool_logs import (last_test_metrics,
                                                   make_converted_world,
                                                   mean_of_class_ious,
                                                   run_tool, train_losses)
from projects.occ_cyl import OccCylindrical
from projects.occ_cyl.cylindrical import CylinderGrid

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG_DIR = osp.join(ROOT, 'configs', 'occ_cyl')
MAIN = sorted(glob.glob(osp.join(CONFIG_DIR, '*.py')))
ABLATIONS = sorted(glob.glob(osp.join(CONFIG_DIR, 'ablations', '*.py')))
PAPER = osp.join(CONFIG_DIR, 'occcyl_r50-swint_3xb1-24e_surroundocc-nus.py')
OCC3D = osp.join(CONFIG_DIR, 'occcyl_r50-swint_3xb1-24e_occ3d-nus.py')
TINY = osp.join(CONFIG_DIR, 'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')


def _flatten(obj, prefix=''):
    """{'a.b[0].c': value} of a nested config."""
    if isinstance(obj, dict):
        out = {}
        for key, value in obj.items():
            out.update(_flatten(value, f'{prefix}.{key}' if prefix else key))
        return out
    if isinstance(obj, (list, tuple)) and any(
            isinstance(v, (dict, list, tuple)) for v in obj):
        out = {}
        for i, value in enumerate(obj):
            out.update(_flatten(value, f'{prefix}[{i}]'))
        return out
    return {prefix: obj}


def _model_diff(path_a, path_b):
    a = _flatten(Config.fromfile(path_a).to_dict()['model'])
    b = _flatten(Config.fromfile(path_b).to_dict()['model'])
    return {k for k in a.keys() | b.keys() if a.get(k) != b.get(k)}


def test_config_inventory():
    """The paper's config, its Occ3D variant, the tiny synthetic config and
    the deltas of Tables V (3 files), VI (2) and VII (3)."""
    assert set(MAIN) == {PAPER, OCC3D, TINY}
    names = {osp.basename(p).split('_')[0] for p in ABLATIONS}
    assert names == {
        'occcyl-nodepthsup', 'occcyl-nodepthfeat', 'occcyl-nopos',
        'occcyl-d2m', 'occcyl-d10m', 'occcyl-m1', 'occcyl-m2', 'occcyl-m4'
    }


@pytest.mark.parametrize(
    'path', MAIN + ABLATIONS, ids=lambda p: osp.basename(p)[:-3])
def test_coupled_values_reach_every_module(path):
    """Imports, grid, cylinder, depth bins and classes agree everywhere, and
    the cylinder covers every voxel of the output grid."""
    cfg = Config.fromfile(path)
    assert cfg.custom_imports == dict(
        imports=['projects.occ_common', 'projects.occ_cyl'],
        allow_failed_imports=False)
    model = cfg.model
    pcr = cfg.point_cloud_range
    grid = [round((pcr[i + 3] - pcr[i]) / cfg.voxel_size[i]) for i in range(3)]
    head = model.occ_head
    assert [list(s) for s in head.scale_shapes
            ] == [[g // 2**lvl for g in grid] for lvl in range(4)]
    assert head.num_classes == len(cfg.class_names)
    assert head.pc_range == pcr
    assert head.cyl_range == model.tpv_fusion.cyl_range
    assert head.grid_shape == model.tpv_fusion.grid_shape
    assert CylinderGrid(head.grid_shape, head.cyl_range).covers_box(pcr)
    # The radius reaches the corners at (max |x|^2 + max |y|^2)^0.5.
    assert head.cyl_range[3] >= math.hypot(pcr[3], pcr[4])
    bound = model.depth_bound
    num_bins = round((bound[1] - bound[0]) / bound[2])
    assert model.depth_net.num_depth_bins == num_bins
    assert model.depth_net.position_channels in (0, 3 * num_bins)
    if model.loss_depth is not None:
        assert model.loss_depth.depth_bound == bound
        assert model.loss_depth.downsample == cfg.img_stride
    for size in model.tpv_fusion.grid_shape:
        assert size % model.tpv_fusion.num_groups == 0
    assert model.tpv_encoder.backbone.in_channels == \
        model.tpv_fusion.plane_channels
    assert cfg.val_evaluator.type == 'OccupancyMetric'
    if path == OCC3D:
        assert cfg.val_evaluator.use_camera_mask
        assert model.loss_mask_key == 'mask_camera'
        assert head.loss_occ.empty_index == cfg.class_names.index('free')


def test_ablation_deltas():
    """Each ablation changes exactly the knob its name says (and what is
    coupled to it), nothing else."""
    expected = {
        'occcyl-nodepthsup': {'loss_depth'},
        'occcyl-nodepthfeat': {'depth_net.with_depth_feature'},
        'occcyl-nopos': {'depth_net.position_channels'},
        'occcyl-m1': {'tpv_fusion.num_groups'},
        'occcyl-m2': {'tpv_fusion.num_groups'},
        'occcyl-m4': {'tpv_fusion.num_groups'},
    }
    bins_keys = {
        'depth_bound', 'depth_net.num_depth_bins',
        'depth_net.position_channels', 'loss_depth.depth_bound'
    }
    expected['occcyl-d2m'] = expected['occcyl-d10m'] = bins_keys
    for path in ABLATIONS:
        name = osp.basename(path).split('_')[0]
        diff = _model_diff(PAPER, path)
        # loss_depth=None removes all its sub-keys.
        diff = {
            k.split('.')[0] if k.startswith('loss_depth.')
            and name == 'occcyl-nodepthsup' else k
            for k in diff
        }
        assert diff == expected[name], name
        model = Config.fromfile(path).model
        if match := re.search(r'-m(\d)$', name):
            assert model.tpv_fusion.num_groups == int(match[1])
        if match := re.search(r'-d(\d+)m$', name):
            # (1, 51, d): 25 bins at d = 2, 5 bins at d = 10 (Table VI).
            assert model.depth_net.num_depth_bins == 50 // int(match[1])


def test_occ3d_differs_only_in_coupled_values():
    """The Occ3D config repeats the paper's model; only the grid, classes,
    empty label, cylinder and the camera-mask loss may differ."""
    diff = _model_diff(PAPER, OCC3D)
    allowed = {
        'tpv_fusion.cyl_range', 'occ_head.cyl_range', 'occ_head.pc_range',
        'occ_head.num_classes', 'occ_head.loss_occ.empty_index',
        'occ_head.loss_occ.losses[2].empty_index',
        'occ_head.loss_occ.losses[3].empty_index', 'loss_mask_key'
    }
    assert diff == allowed


@pytest.mark.parametrize(
    'path', MAIN + ABLATIONS, ids=lambda p: osp.basename(p)[:-3])
def test_model_builds(path):
    """Every config's model builds (the paper one is reported below)."""
    cfg = Config.fromfile(path)
    init_default_scope(cfg.default_scope)  # as the Runner does
    model = MODELS.build(cfg.model)
    assert isinstance(model, OccCylindrical)


def test_paper_model_parameter_count(capsys):
    """The paper config builds a ResNet-50 image backbone: 23,508,032
    parameters (torchvision's 25,557,032 minus the 2048 x 1000 + 1000 fc).
    The total is printed for the report, next to the paper's 111.62 M."""
    cfg = Config.fromfile(PAPER)
    init_default_scope(cfg.default_scope)
    model = MODELS.build(cfg.model)
    backbone = sum(p.numel() for p in model.img_encoder.backbone.parameters())
    assert backbone == 25_557_032 - (2048 * 1000 + 1000)
    parts = {
        name: sum(p.numel() for p in child.parameters())
        for name, child in model.named_children()
    }
    total = sum(p.numel() for p in model.parameters())
    assert total == sum(parts.values())
    with capsys.disabled():
        print(f'\nOccCylindrical paper config: {total / 1e6:.2f} M '
              f'parameters (paper: 111.62 M); ' +
              ', '.join(f'{k} {v / 1e6:.2f} M' for k, v in parts.items() if v))


# ---------------------------------------------------------------------------
# End to end: tools/train.py and tools/test.py on a synthetic world.
# ---------------------------------------------------------------------------
@pytest.fixture(scope='module')
def synthetic_root(tmp_path_factory):
    """Two scenes of two key frames (one for training, one for val), two
    sweeps per key-frame interval, 160x96 images."""
    root = str(tmp_path_factory.mktemp('occcyl') / 'synthetic_nuscenes')
    return make_converted_world(
        root, scenes=2, samples=2, sweeps=2, image_size=(160, 96))


@pytest.mark.slow
def test_tiny_config_trains_and_tests(synthetic_root, tmp_path):
    """The loss falls over 4 epochs of 2 samples (the mean of the last two
    iterations is below that of the first two) and tools/test.py reports
    IoU and mIoU through OccupancyMetric."""
    data = [
        f'{split}_dataloader.dataset.data_root={synthetic_root}'
        for split in ('train', 'val', 'test')
    ]
    work_dir = str(tmp_path / 'work')
    proc = run_tool('train.py', TINY, '--work-dir', work_dir, '--cfg-options',
                    'train_cfg.max_epochs=4', 'train_cfg.val_interval=4',
                    'default_hooks.checkpoint.interval=4', *data)
    assert proc.returncode == 0, proc.stderr[-3000:]
    losses = train_losses(work_dir)
    assert len(losses) == 8
    assert sum(losses[-2:]) < sum(losses[:2])
    proc = run_tool('test.py', TINY, osp.join(work_dir,
                                              'epoch_4.pth'), '--work-dir',
                    str(tmp_path / 'test'), '--cfg-options', *data)
    assert proc.returncode == 0, proc.stderr[-3000:]
    metrics = last_test_metrics(str(tmp_path / 'test'))
    # SurroundOcc: mIoU is the mean over classes 1..16 present in GT or
    # prediction; IoU is occupied vs empty, within (0, 100) once anything is
    # predicted occupied.
    names = Config.fromfile(TINY).class_names[1:]
    assert metrics['occ/mIoU'] == pytest.approx(
        mean_of_class_ious(metrics, names), abs=1e-3)
    assert 0.0 < metrics['occ/IoU'] < 100.0
