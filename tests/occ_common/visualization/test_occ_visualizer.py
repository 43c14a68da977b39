"""mmdet3d's tools/misc/browse_dataset.py draws our samples.

browse_dataset builds ``cfg.visualizer`` from the config, sets its
``dataset_meta`` to the dataset's metainfo and calls
``add_datasample('3d visualzier', item['inputs'],
data_sample=item['data_samples'].numpy(), show=..., wait_time=...,
out_file=..., o3d_save_path=..., vis_task=...)`` per sample.
"""
import os.path as osp
import subprocess
import sys
import warnings

import mmdet3d
import numpy as np
import pytest
from mmengine.config import Config
from mmengine.registry import init_default_scope
from PIL import Image

from projects.occ_common.visualization import (OccLocalVisualizer,
                                               render_data_sample)

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.dirname(
    osp.abspath(__file__)))))
OCC3D_TINY = osp.join(ROOT, 'configs', 'sdg_occ',
                      'sdgocc-kl_tiny_1xb1-6e_occ3d-nus-synthetic.py')
SURROUNDOCC_TINY = osp.join(
    ROOT, 'configs', 'occ_cyl',
    'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')
BROWSE = osp.join(
    osp.dirname(mmdet3d.__file__), '.mim', 'tools', 'misc',
    'browse_dataset.py')


def test_browse_dataset_calls_draw_a_tiny_world_sample(converted_tiny_world,
                                                       tmp_path):
    """The calls of browse_dataset, in this process, on an Occ3D sample:
    the written picture is exactly :func:`render_data_sample` of the packed
    sample with its cameras, with the Occ3D classes and free (17) empty."""
    from mmdet3d.registry import DATASETS, VISUALIZERS
    cfg = Config.fromfile(OCC3D_TINY)
    cfg.train_dataloader.dataset.data_root = converted_tiny_world
    cfg.train_dataloader.dataset.pipeline = cfg.test_pipeline
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    dataset = DATASETS.build(
        cfg.train_dataloader.dataset,
        default_args=dict(filter_empty_gt=False))
    with warnings.catch_warnings():
        warnings.filterwarnings('ignore', 'Failed to add')
        visualizer = VISUALIZERS.build(cfg.visualizer)
    assert isinstance(visualizer, OccLocalVisualizer)
    visualizer.dataset_meta = dataset.metainfo
    item = dataset[0]
    sample = item['data_samples'].numpy()
    out_file = str(tmp_path / '0.png')
    picture = visualizer.add_datasample(
        '3d visualzier', item['inputs'], data_sample=sample, show=False,
        wait_time=0, out_file=out_file, o3d_save_path=None, vis_task=None)
    expected = render_data_sample(
        sample, dataset.metainfo['classes'], 17, img=item['inputs']['img'])
    np.testing.assert_array_equal(picture, expected)
    np.testing.assert_array_equal(np.asarray(Image.open(out_file)), picture)


def test_visualizer_without_dataset_meta_uses_its_convention():
    """No dataset meta: the convention's classes and empty label."""
    vis = OccLocalVisualizer.get_instance('occ_vis_convention_test',
                                          convention='occ3d')
    names, empty = vis._classes()
    assert len(names) == 18 and names[empty] == 'free'
    vis.dataset_meta = dict(occ_format='surroundocc')
    names, empty = vis._classes()
    assert len(names) == 17 and names[empty] == 'empty'
    with pytest.raises(ValueError, match='convention'):
        OccLocalVisualizer(name='occ_vis_bad', convention='kitti')


@pytest.mark.slow
@pytest.mark.skipif(not osp.isfile(BROWSE),
                    reason=f'mmdet3d ships no {BROWSE}')
def test_mmdet3d_browse_dataset_script_runs(converted_tiny_world, tmp_path):
    """mmdet3d 1.4's own script, unmodified, on the SurroundOcc tiny
    config: one picture per training sample (the tiny world's one scene of
    two key frames), each as large as the figure of a sample."""
    out = tmp_path / 'browse'
    proc = subprocess.run(
        [sys.executable, BROWSE, SURROUNDOCC_TINY, '--not-show',
         '--output-dir', str(out), '--cfg-options',
         f'train_dataloader.dataset.data_root={converted_tiny_world}'],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert sorted(p.name for p in out.iterdir()) == ['0.jpg', '1.jpg']
    with Image.open(out / '0.jpg') as picture:
        width, height = picture.size
    # Two columns (GT only: top-down and 3D rows) plus the legend, with
    # the camera rows on top: wider than a 3D view, taller than two.
    assert width > 480 and height > 2 * 360


def test_tensorboard_override_of_the_docs_builds(tmp_path):
    """docs/visualization.md's one-line TensorBoard override gives a valid
    config whose visualizer has both backends. Without the tensorboard package
    (not a dependency) the first logged value fails with mmengine's install
    hint; with it, an event file is written."""
    from mmdet3d.registry import VISUALIZERS
    with open(osp.join(ROOT, 'docs', 'visualization.md')) as f:
        readme = f.read()
    line = next(ln for ln in readme.splitlines()
                if 'TensorboardVisBackend' in ln and 'visualizer' in ln)
    config = tmp_path / 'tb_config.py'
    config.write_text(f'_base_ = [{SURROUNDOCC_TINY!r}]\n{line.strip()}\n')
    cfg = Config.fromfile(str(config))
    init_default_scope('mmdet3d')
    vis = VISUALIZERS.build(
        dict(cfg.visualizer, name='tb_test', save_dir=str(tmp_path / 'log')))
    assert [type(b).__name__ for b in vis._vis_backends.values()] == [
        'LocalVisBackend', 'TensorboardVisBackend']
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError, match='pip install .*tensorboard'):
            vis.add_scalar('loss', 1.0)
        return
    vis.add_scalar('loss', 1.0)
    events = list((tmp_path / 'log' / 'vis_data').rglob('events.out.*'))
    assert events
