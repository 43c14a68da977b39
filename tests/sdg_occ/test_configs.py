"""Every SDG-OCC config builds; the tiny ones train and test end to end."""
import glob
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
from projects.sdg_occ import SDGOcc

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG_DIR = osp.join(ROOT, 'configs', 'sdg_occ')
MAIN = sorted(glob.glob(osp.join(CONFIG_DIR, '*.py')))
ABLATIONS = sorted(glob.glob(osp.join(CONFIG_DIR, 'ablations', '*.py')))
TINY = [path for path in MAIN if '_tiny_' in path]


def test_config_inventory():
    """Both variants on both datasets, two tiny configs and the deltas of
    Tables 3 (2 files; SDG only is the main fusion config), 4 (6) and 5
    (4)."""
    names = {osp.basename(p) for p in MAIN}
    for variant in ('fusion', 'kl'):
        for dataset in ('occ3d-nus', 'surroundocc-nus'):
            assert f'sdgocc-{variant}_r50_4xb2-24e_{dataset}.py' in names
        assert (f'sdgocc-{variant}_tiny_1xb1-6e_occ3d-nus-synthetic.py'
                in names)
    assert len(ABLATIONS) == 12


@pytest.mark.parametrize(
    'path', MAIN + ABLATIONS, ids=lambda p: osp.basename(p)[:-3])
def test_config_loads_with_imports(path):
    cfg = Config.fromfile(path)
    assert cfg.custom_imports == dict(
        imports=['projects.occ_common', 'projects.sdg_occ'],
        allow_failed_imports=False)
    model = cfg.model
    assert model.type == 'SDGOcc'
    assert model.variant == ('kl' if 'sdgocc-kl' in path else 'fusion')
    # The coupled grid values reach every module that needs them.
    grid = [
        round((cfg.point_cloud_range[i + 3] - cfg.point_cloud_range[i]) /
              cfg.voxel_size[i]) for i in range(3)
    ]
    assert list(model.view_transform.bev_shape) == [grid[1], grid[0]]
    assert list(model.lidar_encoder.bev_shape) == [grid[1], grid[0]]
    assert model.occ_head.dz == grid[2]
    assert model.occ_head.num_classes == len(cfg.class_names)
    assert model.fusion.out_channels == model.depth_net.context_channels
    assert model.depth_loss.loss_weight == 0.05
    if 'occ3d' in path:
        assert cfg.val_evaluator.use_camera_mask
        assert model.occ_head.use_camera_mask


def test_ablation_deltas():
    """Each ablation file changes exactly the knob its name says."""
    for path in ABLATIONS:
        name = osp.basename(path)
        model = Config.fromfile(path).model
        if match := re.search(r'-r(\d)l(\d+)_', name):
            assert model.view_transform.layer_radius == float(match[1])
            assert model.view_transform.num_layers == int(match[2])
        elif match := re.search(r'-k(\d)_', name):
            assert model.fusion.kernel_size == int(match[1])
        else:
            assert '-lss_' in name
            assert model.view_transform.use_sdg is False


@pytest.mark.parametrize('path', MAIN, ids=lambda p: osp.basename(p)[:-3])
def test_model_builds(path):
    cfg = Config.fromfile(path)
    init_default_scope(cfg.default_scope)  # as the Runner does
    model = MODELS.build(cfg.model)
    assert isinstance(model, SDGOcc)
    assert model.variant == cfg.model.variant


# ---------------------------------------------------------------------------
# End to end: tools/train.py and tools/test.py on a synthetic world.
# ---------------------------------------------------------------------------
@pytest.fixture(scope='module')
def synthetic_root(tmp_path_factory):
    """Two scenes of two key frames (one for training, one for val)."""
    root = str(tmp_path_factory.mktemp('sdg') / 'synthetic_nuscenes')
    return make_converted_world(
        root, scenes=2, samples=2, sweeps=1, image_size=(352, 198))


@pytest.mark.slow
@pytest.mark.parametrize('path', TINY, ids=lambda p: osp.basename(p)[:-3])
def test_tiny_config_trains_and_tests(path, synthetic_root, tmp_path):
    """Loss falls over 4 epochs of 2 samples and test.py reports a mIoU."""
    data = [
        f'{split}_dataloader.dataset.data_root={synthetic_root}'
        for split in ('train', 'val', 'test')
    ]
    work_dir = str(tmp_path / 'work')
    proc = run_tool('train.py', path, '--work-dir', work_dir, '--cfg-options',
                    'train_cfg.max_epochs=4', 'train_cfg.val_interval=4',
                    'default_hooks.checkpoint.interval=4', *data)
    assert proc.returncode == 0, proc.stderr[-3000:]
    losses = train_losses(work_dir)
    assert len(losses) == 8
    assert sum(losses[-2:]) < sum(losses[:2])
    proc = run_tool('test.py', path, osp.join(work_dir,
                                              'epoch_4.pth'), '--work-dir',
                    str(tmp_path / 'test'), '--cfg-options', *data)
    assert proc.returncode == 0, proc.stderr[-3000:]
    metrics = last_test_metrics(str(tmp_path / 'test'))
    # Occ3D: mIoU is the mean over classes 0..16 (not 'free') present in
    # the camera-masked GT or prediction.
    names = Config.fromfile(path).class_names[:-1]
    assert metrics['occ/mIoU'] == pytest.approx(
        mean_of_class_ious(metrics, names), abs=1e-3)
    assert 0.0 < metrics['occ/IoU'] < 100.0
