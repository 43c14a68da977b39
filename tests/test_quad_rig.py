"""A rig other than nuScenes': four cameras and a LiDAR without ring index.

The synthetic generator writes the rig (``--camera-rig quad
--no-lidar-ring``), tools/create_data.py links the four cameras of its
sensor table and records 4 values per point, the dataset keeps the info
file's cameras, the pipelines read the point layout from the info file,
both models train on four views, the dataset doctor passes the rig, and
the rig's configs (configs/*/*quad-synthetic.py) train and test end to
end (slow tier).
"""
import glob
import os.path as osp
import warnings

import numpy as np
import pytest
import torch
from mmdet3d.registry import DATASETS, MODELS
from mmengine.config import Config
from mmengine.dataset import pseudo_collate
from mmengine.registry import init_default_scope

import projects.occ_common  # noqa: F401  (registers)
from projects.occ_common.analysis.dataset_doctor import run_doctor
from projects.occ_common.analysis.tool_runs import data_options
from projects.occ_common.fileio.safe_pickle import load_info_file
from projects.occ_common.synthetic import QUAD_CAMERA_NAMES
from projects.occ_common.testing.tiny_world import make_tiny_world
from projects.occ_common.testing.tool_logs import (REPO_ROOT,
                                                   last_test_metrics,
                                                   run_create_data, run_tool,
                                                   train_losses)

QUAD = sorted(glob.glob(osp.join(REPO_ROOT, 'configs', '*',
                                 '*quad-synthetic.py')))
SDG_QUAD, OCCCYL_QUAD = (
    next(p for p in QUAD if 'sdg_occ' in p),
    next(p for p in QUAD if 'occ_cyl' in p))
OCCCYL_TINY = osp.join(REPO_ROOT, 'configs', 'occ_cyl',
                       'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')


@pytest.fixture(scope='module')
def quad_root(tmp_path_factory):
    """The tiny world (one scene of two key frames, 160x90 images) on the
    four-camera rig whose LiDAR has no ring index, converted."""
    root = make_tiny_world(str(tmp_path_factory.mktemp('quad_world')),
                           camera_rig='quad', lidar_ring=False)
    with warnings.catch_warnings():
        warnings.filterwarnings('ignore', 'synthetic world with one scene')
        run_create_data('--root-path', root, '--version', 'v1.0-mini')
    return root.rstrip('/') + '/'


def _dataset(path, root, split='train', **overrides):
    cfg = Config.fromfile(path)
    init_default_scope('mmdet3d')
    ds_cfg = cfg[f'{split}_dataloader'].dataset
    return DATASETS.build(dict(ds_cfg, data_root=root, **overrides)), cfg


def test_conversion_records_the_rig(quad_root):
    """The info files list the four cameras in the generator's order and 4
    values per LiDAR point; every key frame file holds whole points of 16
    bytes (1,6xx points of the 80-step LiDAR)."""
    infos = load_info_file(osp.join(quad_root, 'nuscenes_occ_infos_val.pkl'))
    assert infos['metainfo']['cameras'] == QUAD_CAMERA_NAMES
    for entry in infos['data_list']:
        assert tuple(entry['images']) == QUAD_CAMERA_NAMES
        assert entry['lidar_points']['num_pts_feats'] == 4
        size = osp.getsize(
            osp.join(quad_root, entry['lidar_points']['lidar_path']))
        assert size % 16 == 0 and 1500 < size // 16 < 2500


def test_dataset_keeps_the_info_files_cameras(quad_root):
    """cam_names=None keeps the info file's four cameras; nuScenes' six are
    refused, naming the missing ones."""
    dataset, _ = _dataset(SDG_QUAD, quad_root, cam_names=None)
    assert dataset.metainfo['cam_names'] == QUAD_CAMERA_NAMES
    assert tuple(dataset.get_data_info(0)['images']) == QUAD_CAMERA_NAMES
    with pytest.raises(ValueError, match='CAM_FRONT_RIGHT'):
        _dataset(OCCCYL_TINY, quad_root)


@pytest.mark.parametrize('path', QUAD, ids=lambda p: osp.basename(p)[:-3])
def test_rig_config_pipelines(quad_root, path):
    """A training sample of each rig config: four views of the config's
    image size with one (4, 4) projection each, and points of x, y, z,
    intensity, time lag (the key frame's lag 0; SDG's tiny config merges
    no sweeps, OccCylindrical's small one 10 of them, 0.05 s apart)."""
    dataset, cfg = _dataset(path, quad_root)
    sample = dataset[0]
    assert tuple(sample['inputs']['img'].shape) == (4, 3, *cfg.img_size)
    meta = sample['data_samples'].metainfo
    assert meta['cam_names'] == list(QUAD_CAMERA_NAMES)
    assert np.asarray(meta['lidar2img']).shape == (4, 4, 4)
    points = sample['inputs']['points'].numpy()
    assert points.shape[1] == 5
    lags = np.unique(np.round(points[:, 4], 3))
    assert lags[0] == 0.0
    if 'sdg_occ' in path:
        assert len(lags) == 1
    else:
        assert len(lags) == 11 and lags[-1] == pytest.approx(0.5)


@pytest.mark.parametrize('path', [SDG_QUAD, OCCCYL_TINY],
                         ids=['sdgocc-fusion-tiny-quad', 'occcyl-tiny'])
def test_one_training_step_on_four_views(quad_root, path):
    """One training step of SDG-Fusion's rig config and of the tiny
    OccCylindrical (the rig's own, the small model, trains in the slow
    tier) on the rig's first sample: every loss term finite, and every
    parameter with a gradient has a finite one."""
    dataset, cfg = _dataset(path, quad_root, cam_names=None)
    torch.manual_seed(0)
    model = MODELS.build(cfg.model)
    data = model.data_preprocessor(pseudo_collate([dataset[0]]), True)
    assert data['inputs']['imgs'].shape[1] == 4
    losses = model(**data, mode='loss')
    total = sum(v for k, v in losses.items() if k.startswith('loss'))
    assert torch.isfinite(total)
    total.backward()
    grads = [p.grad for p in model.parameters() if p.grad is not None]
    assert grads and all(torch.isfinite(g).all() for g in grads)


def test_the_doctor_passes_the_rig(quad_root):
    """Occ3D labels of the rig: every check passes (labels on the points,
    masks traced from the four cameras and the LiDAR), and the
    calibration check measured the four cameras."""
    report = run_doctor(Config.fromfile(SDG_QUAD), 'val',
                        data_root=quad_root)
    assert report.verdict == 'pass', [
        s.findings for s in report.summaries.values() if s.findings]
    numbers = report.summaries['calibration'].numbers
    assert {k.split('.')[0] for k in numbers
            if k.endswith('.points_in_view')} == set(QUAD_CAMERA_NAMES)
    assert report.summaries['masks'].numbers['points_in_lidar_mask'][
        'min'] == 1.0


@pytest.fixture(scope='module')
def quad_world(tmp_path_factory):
    """Two scenes of two key frames (one trains, one validates), 352x198
    images, two sweeps per key-frame interval, on the rig, through the
    command-line tools."""
    root = str(tmp_path_factory.mktemp('quad') / 'synthetic_quad')
    for script, args in (
            ('tools/dataset_converters/create_synthetic_nuscenes.py',
             [root, '--scenes', '2', '--samples', '2', '--sweeps', '2',
              '--image-size', '352', '198', '--camera-rig', 'quad',
              '--no-lidar-ring']),
            ('tools/create_data.py', ['nuscenes', '--root-path', root,
                                      '--version', 'v1.0-mini'])):
        proc = run_tool(script, *args)
        assert proc.returncode == 0, proc.stderr[-3000:]
    return root + '/'


@pytest.mark.slow
@pytest.mark.parametrize('path', QUAD, ids=lambda p: osp.basename(p)[:-3])
def test_rig_config_trains_and_tests(quad_world, path, tmp_path):
    """tools/train.py for 4 epochs of 2 samples: the mean loss of the
    last two iterations is below that of the first two; tools/test.py
    reports IoU and mIoU (the mean of the class IoUs it logs)."""
    data = data_options(quad_world, path)
    work = str(tmp_path / 'work')
    proc = run_tool('tools/train.py', path, '--work-dir', work,
                    '--cfg-options', 'train_cfg.max_epochs=4',
                    'train_cfg.val_interval=4',
                    'default_hooks.checkpoint.interval=4', *data,
                    timeout=1800)
    assert proc.returncode == 0, proc.stderr[-3000:]
    losses = train_losses(work)
    assert len(losses) == 8
    assert sum(losses[-2:]) < sum(losses[:2])
    test_dir = str(tmp_path / 'test')
    proc = run_tool('tools/test.py', path, osp.join(work, 'epoch_4.pth'),
                    '--work-dir', test_dir, '--cfg-options', *data)
    assert proc.returncode == 0, proc.stderr[-3000:]
    metrics = last_test_metrics(test_dir)
    cfg = Config.fromfile(path)
    names = [n for i, n in enumerate(cfg.class_names)
             if i != cfg.empty_index]
    ious = [metrics[f'occ/{n}'] for n in names
            if not np.isnan(metrics[f'occ/{n}'])]
    assert metrics['occ/mIoU'] == pytest.approx(np.mean(ious), abs=1e-3)
    assert 0.0 <= metrics['occ/IoU'] < 100.0
    print(f'{osp.basename(path)}: losses {losses}, IoU '
          f'{metrics["occ/IoU"]:.2f}, mIoU {metrics["occ/mIoU"]:.2f}')
