"""OccVisualizationHook writes one picture per evaluated sample."""
import logging
import os
import os.path as osp
import time
import types
import uuid

import numpy as np
import pytest
import torch
from mmengine.logging import MessageHub
from mmengine.structures import BaseDataElement

from projects.occ_common.engine.hooks import OccVisualizationHook
from projects.occ_common.evaluation import OccupancyMetric
from projects.occ_common.testing.tool_logs import REPO_ROOT as ROOT

NAMES = ('empty', 'car', 'road')
FAST = dict(view_size=(40, 60))

TOY_CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


class _Visualizer:
    """Records add_image calls as the Runner's visualiser would get them."""

    def __init__(self):
        self.images = []

    def add_image(self, name, image, step=0):
        self.images.append((name, image.shape, step))


def _runner(log_dir, metrics=(), classes=NAMES):
    """The Runner attributes the hook uses."""
    loop = types.SimpleNamespace(
        evaluator=types.SimpleNamespace(metrics=list(metrics)),
        dataloader=types.SimpleNamespace(
            dataset=types.SimpleNamespace(metainfo=dict(classes=classes))))
    return types.SimpleNamespace(
        log_dir=str(log_dir), logger=logging.getLogger('occ_vis_test'),
        test_loop=loop, val_loop=loop, rank=0, iter=11,
        visualizer=_Visualizer(),
        message_hub=MessageHub.get_instance(f'occ_vis_{uuid.uuid4().hex}'))


def _samples(*indices, **metainfo):
    """Data samples with a 8x8x4 GT (road floor) and a prediction."""
    out = []
    for idx in indices:
        sample = BaseDataElement(metainfo=dict(sample_idx=idx, **metainfo))
        gt = torch.zeros(8, 8, 4, dtype=torch.long)
        gt[:, :, 0] = 2
        sample.gt_occ = gt
        sample.pred_occ = torch.roll(gt, idx, dims=0)
        out.append(sample)
    return out


def test_test_mode_writes_one_png_per_sample(tmp_path):
    """Two batches of 2 and 1 samples -> 0.png, 1.png, 2.png."""
    hook = OccVisualizationHook(draw=True, test_out_dir='show', **FAST)
    runner = _runner(tmp_path)
    hook.before_test(runner)
    hook.after_test_iter(runner, 0, outputs=_samples(0, 1))
    hook.after_test_iter(runner, 1, outputs=_samples(2))
    assert sorted(os.listdir(tmp_path / 'show')) == [
        '0.png', '1.png', '2.png']


def test_pictures_are_named_after_scene_and_token(tmp_path):
    """``<scene_name>_<token>.png``, ``<token>.png`` without a scene name,
    ``<sample_idx>.png`` without a token (before: always sample_idx, the
    index in the info file, so 0.png for the first sample of every
    split). A token that cannot name a file (``t/1``) is refused, naming
    it (before: written as ``t_1.png``, which ``t_1`` would overwrite)."""
    token = 'ca9a282c9e77460f8360f564131a8af5'
    hook = OccVisualizationHook(draw=True, test_out_dir='show', **FAST)
    runner = _runner(tmp_path)
    hook.before_test(runner)
    hook.after_test_iter(runner, 0, outputs=_samples(
        0, token=token, scene_name='scene-0061'))
    hook.after_test_iter(runner, 1, outputs=_samples(1, token='t_1'))
    hook.after_test_iter(runner, 2, outputs=_samples(2))
    assert sorted(os.listdir(tmp_path / 'show')) == [
        '2.png', f'scene-0061_{token}.png', 't_1.png']
    with pytest.raises(ValueError, match="sample name 't/1' cannot name a "
                       'file'):
        hook.after_test_iter(runner, 3, outputs=_samples(3, token='t/1'))


def test_interval_and_draw_false(tmp_path):
    """interval 2 draws samples 0 and 2 of 0..2; draw=False draws none."""
    hook = OccVisualizationHook(draw=True, interval=2,
                                test_out_dir=str(tmp_path / 'abs'), **FAST)
    runner = _runner(tmp_path / 'log')
    hook.before_test(runner)
    hook.after_test_iter(runner, 0, outputs=_samples(0, 1))
    hook.after_test_iter(runner, 1, outputs=_samples(2))
    hook.after_test_iter(runner, 2, outputs=[])
    assert sorted(os.listdir(tmp_path / 'abs')) == ['0.png', '2.png']
    off = OccVisualizationHook(test_out_dir='off', **FAST)
    off.before_test(runner)
    off.after_test_iter(runner, 0, outputs=_samples(0))
    assert not (tmp_path / 'log' / 'off').exists()


def test_validation_and_test_without_folder_use_the_visualiser(tmp_path):
    """Pictures go to visualizer.add_image as '{mode}_occ_{sample}'."""
    hook = OccVisualizationHook(draw=True, **FAST)
    runner = _runner(tmp_path)
    hook.before_val(runner)
    hook.after_val_iter(runner, 0, outputs=_samples(4))
    hook.before_test(runner)
    hook.after_test_iter(runner, 0, outputs=_samples(5))
    names = [(name, step) for name, _, step in runner.visualizer.images]
    assert names == [('val_occ_4', 11), ('test_occ_5', 11)]
    assert runner.visualizer.images[0][1][2] == 3
    assert os.listdir(tmp_path) == []


def test_classes_come_from_the_metric_then_the_dataset(tmp_path):
    """OccupancyMetric wins; else dataset classes + convention's empty."""
    metric = OccupancyMetric(convention='occ3d',
                             class_names=('others', 'car', 'free'))
    hook = OccVisualizationHook(draw=True)
    assert hook._classes(_runner(tmp_path, [metric]), 'test') == (
        ('others', 'car', 'free'), 2)
    assert hook._classes(_runner(tmp_path), 'test') == (NAMES, 0)
    occ3d = OccVisualizationHook(convention='occ3d')
    names, empty = occ3d._classes(_runner(tmp_path, classes=()), 'val')
    assert (len(names), empty) == (18, 17)


def test_camera_images_are_taken_from_the_batch(tmp_path):
    """draw_cameras with inputs['img'] and lidar2img adds the camera row."""
    from projects.occ_common.synthetic.occ_inputs import ring_camera_rig
    cam2img, lidar2cam = ring_camera_rig(2, (16, 32), 16.0)
    sample = _samples(0)[0]
    sample.set_metainfo(dict(
        lidar2img=(cam2img @ lidar2cam).numpy(),
        occ_pc_range=np.array([-4.0, -4.0, -1.0, 4.0, 4.0, 1.0]),
        occ_voxel_size=np.array([1.0, 1.0, 0.5])))
    batch = dict(inputs=dict(img=[torch.zeros(2, 3, 16, 32,
                                              dtype=torch.uint8)]))
    plain, cams = (OccVisualizationHook(draw=True, draw_cameras=flag, **FAST)
                   for flag in (False, True))
    runner = _runner(tmp_path)
    for hook in (plain, cams):
        hook.after_val_iter(runner, 0, data_batch=batch, outputs=[sample])
    (_, plain_shape, _), (_, cams_shape, _) = runner.visualizer.images
    assert cams_shape[0] > plain_shape[0]


def test_bad_arguments_are_rejected():
    """--show needs a display; interval < 1; nothing to draw; convention."""
    with pytest.raises(ValueError, match='--show-dir'):
        OccVisualizationHook(draw=True, show=True)
    with pytest.raises(ValueError, match='interval >= 1'):
        OccVisualizationHook(interval=0)
    with pytest.raises(ValueError, match='nothing to draw'):
        OccVisualizationHook(draw_gt=False, draw_pred=False)
    with pytest.raises(ValueError, match="'kitti'"):
        OccVisualizationHook(convention='kitti')


def test_drawing_time_is_vis_time_not_data_time(tmp_path, monkeypatch):
    """A Runner testing the toy config (4 samples, batch 1) with a drawing
    that sleeps 0.2 s per sample.

    mmengine's IterTimerHook logs as data_time the time from its own
    after_test_iter to the next before_test_iter. When the drawing ran
    after the timer (both NORMAL, the hook registered later), batches 2-4
    had data_time >= 0.2 s; now it runs before it: data_time is the toy
    loading (milliseconds), each batch logs vis_time >= 0.2 s, and the
    iteration's time, which the ETA uses, includes the drawing.
    """
    from mmengine.config import Config
    from mmengine.runner import Runner

    from projects.occ_common.engine.hooks import occ_visualization_hook

    sleep = 0.2

    def slow_render(*args, **kwargs):
        time.sleep(sleep)
        return np.zeros((4, 4, 3), np.uint8)

    monkeypatch.setattr(occ_visualization_hook, 'render_data_sample',
                        slow_render)
    cfg = Config.fromfile(TOY_CONFIG)
    cfg.work_dir = str(tmp_path)
    cfg.experiment_name = f'vis_time_{uuid.uuid4().hex}'
    cfg.test_dataloader.batch_size = 1
    cfg.default_hooks.visualization.update(draw=True, test_out_dir='show')
    runner = Runner.from_cfg(cfg)
    runner.test()
    hub = runner.message_hub
    data_time = hub.get_scalar('test/data_time').data[0]
    vis_time = hub.get_scalar('test/vis_time').data[0]
    iter_time = hub.get_scalar('test/time').data[0]
    assert len(data_time) == len(vis_time) == len(iter_time) == 4
    assert data_time.max() < sleep / 2, data_time
    assert vis_time.min() >= sleep, vis_time
    assert iter_time.min() >= sleep, iter_time
    assert len(os.listdir(osp.join(runner.log_dir, 'show'))) == 4
