"""tools/test.py --format-only on a split without labels (v1.0-test).

The tiny world's val infos are turned into a test split as
``create_data.py --version v1.0-test`` writes it (no lidarseg, no
occupancy paths) and every label folder is deleted, so a run that read a
label would fail. Each tiny config writes its convention's files: one per
key frame, named, typed and shaped as the benchmark expects.
"""
import os
import os.path as osp
import pickle
import shutil
import zipfile

import numpy as np
import pytest
import torch
from mmengine.config import Config
from mmengine.registry import init_default_scope

from projects.occ_common.fileio.safe_pickle import load_info_file
from projects.occ_common.testing.tool_logs import load_tool, run_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIGS = {
    'occ3d': osp.join(ROOT, 'configs', 'sdg_occ',
                      'sdgocc-kl_tiny_1xb1-6e_occ3d-nus-synthetic.py'),
    'surroundocc': osp.join(
        ROOT, 'configs', 'occ_cyl',
        'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py'),
}


def _unlabelled_test_split(world: str) -> list:
    """Write nuscenes_occ_infos_test.pkl without label paths, delete the
    label folders; returns the test infos."""
    infos = load_info_file(osp.join(world, 'nuscenes_occ_infos_val.pkl'))
    infos['metainfo']['split'] = 'test'
    for info in infos['data_list']:
        for key in ('pts_semantic_mask_path', 'occ_surroundocc_path',
                    'occ_occ3d_path'):
            info[key] = None
    with open(osp.join(world, 'nuscenes_occ_infos_test.pkl'), 'wb') as f:
        pickle.dump(infos, f)
    for folder in ('gts', 'nuscenes_occ', 'lidarseg'):
        shutil.rmtree(osp.join(world, folder))
    return infos['data_list']


def _checkpoint(config: str, path: str) -> str:
    """The config's freshly initialised model, saved as a checkpoint."""
    from mmdet3d.registry import MODELS
    init_default_scope('mmdet3d')
    torch.manual_seed(0)
    model = MODELS.build(Config.fromfile(config).model)
    torch.save({'meta': {}, 'state_dict': model.state_dict()}, path)
    return path


def test_format_only_edits_only_the_test_config(tmp_path):
    """--format-only: the metric writes to <work_dir>/submission and scores
    nothing; the test pipeline keeps LoadOccupancyGT (allowing unlabelled
    samples) and loses the lidarseg steps; the val config is unchanged."""
    tool = load_tool('tools/test.py')
    args = tool.parse_args([CONFIGS['occ3d'], 'ckpt.pth', '--format-only',
                            '--work-dir', str(tmp_path)])
    cfg = tool.build_cfg(args)
    assert cfg.test_evaluator.format_only is True
    assert cfg.test_evaluator.submission_prefix == str(tmp_path /
                                                       'submission')
    assert 'format_only' not in cfg.val_evaluator
    steps = [s['type'] for s in cfg.test_dataloader.dataset.pipeline]
    val_steps = [s['type'] for s in cfg.val_dataloader.dataset.pipeline]
    assert set(val_steps) - set(steps) == {'LoadLidarSegLabels',
                                           'PointsToSemanticMaps'}
    load = next(s for s in cfg.test_dataloader.dataset.pipeline
                if s['type'] == 'LoadOccupancyGT')
    assert load['allow_unlabelled'] is True
    assert 'allow_unlabelled' not in next(
        s for s in cfg.val_dataloader.dataset.pipeline
        if s['type'] == 'LoadOccupancyGT')


@pytest.mark.slow
@pytest.mark.parametrize('convention', ['occ3d', 'surroundocc'])
def test_format_only_on_a_split_without_labels(world_copy, tmp_path,
                                               convention):
    """One file per test key frame: Occ3D <token>.npz with uint8
    (200, 200, 16) labels 0..17 (and the zip of the folder), SurroundOcc
    <LiDAR file>.npy with uint8 (N, 4) rows of labels 1..16."""
    infos = _unlabelled_test_split(world_copy)
    config = CONFIGS[convention]
    ckpt = _checkpoint(config, str(tmp_path / 'model.pth'))
    work = str(tmp_path / 'work')
    proc = run_tool(
        'tools/test.py', config, ckpt, '--format-only', '--work-dir', work,
        '--cfg-options',
        f'test_dataloader.dataset.data_root={world_copy}',
        'test_dataloader.dataset.ann_file=nuscenes_occ_infos_test.pkl',
        timeout=600)
    assert proc.returncode == 0, proc.stderr[-4000:]
    folder = osp.join(work, 'submission')
    if convention == 'occ3d':
        expected = sorted(f'{info["token"]}.npz' for info in infos)
        with zipfile.ZipFile(folder + '.zip') as archive:
            assert sorted(archive.namelist()) == [
                f'submission/{name}' for name in expected]
    else:
        expected = sorted(
            osp.basename(info['lidar_points']['lidar_path']) + '.npy'
            for info in infos)
    assert sorted(os.listdir(folder)) == expected
    for name in expected:
        path = osp.join(folder, name)
        if convention == 'occ3d':
            with np.load(path, allow_pickle=False) as data:
                grid = data['semantics']
                np.testing.assert_array_equal(data['arr_0'], grid)
                np.testing.assert_array_equal(data['pred'], grid)
            assert grid.dtype == np.uint8 and grid.shape == (200, 200, 16)
            assert grid.max() <= 17
        else:
            rows = np.load(path, allow_pickle=False)
            assert rows.dtype == np.uint8 and rows.ndim == 2
            assert rows.shape[1] == 4
            if len(rows):
                assert (rows[:, :2] < 200).all() and (rows[:, 2] < 16).all()
                assert 1 <= rows[:, 3].min() and rows[:, 3].max() <= 16
