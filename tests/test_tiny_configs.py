"""The tiny configs of both models train and test end to end.

tools/train.py and tools/test.py run as a user would, on one synthetic
world of two scenes with two key frames each (one scene trains, one
validates), 352x198 images and two sweeps per key-frame interval. One
config per project trains end to end (OccCylindrical; SDG-KL, whose
training runs SDG-Fusion's LiDAR branch and fusion as its teacher); the
other SDG-OCC variants are tested on fresh weights through tools/test.py,
their training steps being tests/test_amp_tiny_configs.py's (every tiny
config, float32 and autocast) and tests/test_paper_configs_ddp.py's.
"""
import glob
import os.path as osp

import pytest
import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope

from projects.occ_common.analysis.tool_runs import data_options
from projects.occ_common.testing.tool_logs import (REPO_ROOT,
                                                   last_test_metrics,
                                                   make_converted_world,
                                                   mean_of_class_ious,
                                                   run_tool, train_losses)

#: The four-camera rig's configs train on their own world
#: (tests/test_quad_rig.py).
TINY = sorted(
    p for p in glob.glob(osp.join(REPO_ROOT, 'configs', '*', '*_tiny_*.py'))
    if '-quad-' not in p)
#: Trained end to end: one config per project.
TRAINED = [p for p in TINY if osp.basename(p).startswith(('occcyl_tiny',
                                                          'sdgocc-kl_tiny'))]
#: The no-mask deltas change the loss's mask and the metrics, not the
#: model; SDG-Fusion's single- and two-frame models train inside SDG-KL's
#: run (its teacher) and in the step tests: they are tested, not trained
#: again.
TESTED = [p for p in TINY if p not in TRAINED]


@pytest.fixture(scope='module')
def synthetic_root(tmp_path_factory):
    root = str(tmp_path_factory.mktemp('tiny') / 'synthetic_nuscenes')
    return make_converted_world(
        root, scenes=2, samples=2, sweeps=2, image_size=(352, 198))


def test_every_model_has_a_tiny_config():
    """OccCylindrical, SDG-Fusion (single-frame, over two key frames, and
    trained without the camera mask, scored with RayIoU) and SDG-KL."""
    assert [osp.basename(p)[:-3] for p in TINY] == [
        'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic',
        'sdgocc-fusion-2f_tiny_1xb1-6e_occ3d-nus-synthetic',
        'sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-nomask-synthetic',
        'sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic',
        'sdgocc-kl_tiny_1xb1-6e_occ3d-nus-synthetic',
    ]


@pytest.mark.slow
@pytest.mark.parametrize('path', TRAINED, ids=lambda p: osp.basename(p)[:-3])
def test_tiny_config_trains_and_tests(path, synthetic_root, tmp_path):
    """The loss falls over 4 epochs of 2 samples (the mean of the last two
    iterations is below that of the first two) and tools/test.py reports
    IoU and mIoU through OccupancyMetric."""
    data = data_options(synthetic_root, path)
    work_dir = str(tmp_path / 'work')
    proc = run_tool('tools/train.py', path, '--work-dir', work_dir,
                    '--cfg-options', 'train_cfg.max_epochs=4',
                    'train_cfg.val_interval=4',
                    'default_hooks.checkpoint.interval=4', *data)
    assert proc.returncode == 0, proc.stderr[-3000:]
    losses = train_losses(work_dir)
    assert len(losses) == 8
    assert sum(losses[-2:]) < sum(losses[:2])
    _test_and_check(path, osp.join(work_dir, 'epoch_4.pth'), data,
                    str(tmp_path / 'test'))


@pytest.mark.slow
@pytest.mark.parametrize('path', TESTED, ids=lambda p: osp.basename(p)[:-3])
def test_tiny_config_tests_on_fresh_weights(path, synthetic_root, tmp_path):
    """tools/test.py of the other tiny configs on their freshly built
    model's weights reports the voxel metric and, for the no-mask config,
    RayIoU (@1, @2, @4 and their mean); that the no-mask loss trains
    without the mask is tests/sdg_occ/test_sdg_occ.py's business."""
    cfg = Config.fromfile(path)
    init_default_scope('mmdet3d')
    torch.manual_seed(0)
    checkpoint = str(tmp_path / 'init.pth')
    torch.save(dict(state_dict=MODELS.build(cfg.model).state_dict()),
               checkpoint)
    metrics = _test_and_check(path, checkpoint,
                              data_options(synthetic_root, path),
                              str(tmp_path / 'test'))
    assert ('occ/RayIoU' in metrics) == ('-nomask' in path)


def _test_and_check(path, checkpoint, data, work_dir):
    """tools/test.py; check the metrics it reports (see below) and return
    them."""
    proc = run_tool('tools/test.py', path, checkpoint, '--work-dir',
                    work_dir, '--cfg-options', *data)
    assert proc.returncode == 0, proc.stderr[-3000:]
    metrics = last_test_metrics(work_dir)
    # mIoU is the mean over the classes but the empty one (SurroundOcc's
    # 0, Occ3D's 17 'free') present in the GT or prediction (Occ3D: in the
    # camera mask); IoU is occupied vs empty, in [0, 100): 8 iterations are
    # too few to require occupied predictions (the tiny OccCylindrical,
    # warming up its learning rate, still predicts every voxel empty after
    # them: IoU 0). That the models learn is
    # tools/analysis_tools/benchmark_learning.py's
    # business; this test checks that they train and are scored.
    cfg = Config.fromfile(path)
    names = [n for i, n in enumerate(cfg.class_names) if i != cfg.empty_index]
    assert metrics['occ/mIoU'] == pytest.approx(
        mean_of_class_ious(metrics, names), abs=1e-3)
    assert 0.0 <= metrics['occ/IoU'] < 100.0
    evaluators = cfg.test_evaluator
    if isinstance(evaluators, dict):
        evaluators = [evaluators]
    if any(e['type'] == 'OccRayIoUMetric' for e in evaluators):
        # The classes scored at every threshold are the same (a class is
        # left out where neither GT nor prediction has a ray of it), so
        # the overall value is the mean of the three thresholds'.
        at = [metrics[f'occ/RayIoU@{tau}'] for tau in (1, 2, 4)]
        assert metrics['occ/RayIoU'] == pytest.approx(sum(at) / 3, abs=1e-3)
        assert 0.0 <= min(at) and max(at) <= 100.0
    return metrics


@pytest.mark.slow
def test_compile_true_trains_and_tests_through_the_runner(
        synthetic_root, tmp_path):
    """``compile`` in the config (here ``dict(backend='eager')``: Dynamo
    without inductor, to keep it to a minute) through tools/train.py
    (mmengine compiles train_step) and tools/test.py (TorchCompileHook
    compiles test_step): SDG-KL trains one epoch, and the compiled test of
    its checkpoint reports the eager test's IoU and mIoU (equal to 1e-6;
    the compiled code takes the GPU's code path, the same values by the
    tests of each change)."""
    path = next(p for p in TRAINED if 'sdgocc-kl' in p)
    data = data_options(synthetic_root, path)
    compiled = ['compile.backend=eager']
    work_dir = str(tmp_path / 'work')
    proc = run_tool('tools/train.py', path, '--work-dir', work_dir,
                    '--cfg-options', 'train_cfg.max_epochs=1',
                    'train_cfg.val_interval=1',
                    'default_hooks.checkpoint.interval=1', *data, *compiled)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert len(train_losses(work_dir)) == 2
    checkpoint = osp.join(work_dir, 'epoch_1.pth')
    results = []
    for extra in ([], compiled):
        test_dir = str(tmp_path / f'test{len(extra)}')
        proc = run_tool('tools/test.py', path, checkpoint, '--work-dir',
                        test_dir, '--cfg-options', *data, *extra)
        assert proc.returncode == 0, proc.stderr[-3000:]
        results.append(last_test_metrics(test_dir))
    eager, fast = results
    logs = glob.glob(osp.join(str(tmp_path), 'test1', '*', '*.log'))
    assert any('TorchCompileHook: test_step compiled' in open(f).read()
               for f in logs)
    for key in ('occ/IoU', 'occ/mIoU'):
        assert fast[key] == pytest.approx(eager[key], abs=1e-6)
