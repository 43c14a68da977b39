"""tools/analysis_tools/benchmark.py on the toy config: keys, counts and
ratios."""
import json
import os.path as osp

import numpy as np
import pytest
import torch

from projects.occ_common.testing.tool_logs import load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')
SDG_CONFIG = osp.join(ROOT, 'configs', 'sdg_occ',
                      'sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py')


def _tool():
    return load_tool('tools/analysis_tools/benchmark.py')


def test_single_model_json(tmp_path, capsys):
    """Toy model: Conv3d(3, 3, 1) has 3 * 3 * 1 * 1 * 1 + 3 = 12 params."""
    out = tmp_path / 'bench.json'
    _tool().main([CONFIG, '--runs', '4', '--warmup', '1', '--device', 'cpu',
                  '--fuse-conv-bn', '--json', str(out)])
    report = json.loads(out.read_text())
    assert {'device', 'threads', 'warmup', 'torch', 'models'} <= set(report)
    (model, ) = report['models']
    assert model['params'] == model['trainable_params'] == 12
    assert model['folded_bn'] == 0  # the toy has no ResNet backbone
    assert model['model'] == 'ToyOccupancyModel' and model['batch_size'] == 1
    latency = model['latency_ms']
    assert len(latency['runs']) == 4
    assert 0 < latency['min'] <= latency['p25'] <= latency['median'] \
        <= latency['p75'] <= latency['max']
    assert latency['median'] == pytest.approx(np.median(latency['runs']))
    assert model['peak_memory_mb'] > 0 and model['forward_memory_mb'] >= 0
    assert model['memory_kind'] == 'cpu_rss_high_water'
    # Conv3d(3, 3, 1) on the toy's 8 x 8 x 4 grid: 256 voxels x 3 x 3
    # multiply-adds x 2 = 4,608 FLOP. The share is that work over the
    # median wall time and the matmul rate measured in the same run.
    assert model['gflop'] * 1e9 == pytest.approx(4608)
    assert len(model['cpu_ms']['runs']) == 4
    assert model['matmul_share'] == pytest.approx(
        model['gflop'] / (latency['median'] / 1000) / report['matmul_gflops'])
    # The reference rate is timed in each of the 4 rounds beside the model
    # (not once before it), and the share uses the median of those rounds.
    rounds = report['matmul_gflops_rounds']
    assert len(rounds['runs']) == 4
    assert report['matmul_gflops'] == pytest.approx(np.median(rounds['runs']))
    table = capsys.readouterr().out
    assert 'latency median (ms)' in table and 'ratio' not in table
    assert report['malloc'] == 'default' and 'malloc default' in table


def test_keep_freed_memory_tunes_glibc_before_the_models(monkeypatch,
                                                         capsys):
    """--keep-freed-memory sets the glibc thresholds (1 GiB, 2**31 - 1)
    before any model is built, and the table says so. The call is recorded
    instead of made: the test process's own allocator stays as it is."""
    tool = _tool()
    calls = []

    def tune(mmap_threshold, trim_threshold):
        calls.append((mmap_threshold, trim_threshold))
        return True

    built = []
    subject = tool.Subject
    monkeypatch.setattr(tool, 'tune_glibc_malloc', tune)
    monkeypatch.setattr(
        tool, 'Subject',
        lambda *a: built.append(len(calls)) or subject(*a))
    report = tool.main([CONFIG, '--runs', '1', '--warmup', '0', '--device',
                        'cpu', '--matmul-size', '0', '--keep-freed-memory'])
    assert calls == [(1 << 30, 2**31 - 1)] and built == [1]
    assert report['malloc'] == 'keeps freed memory'
    assert 'malloc keeps freed memory' in capsys.readouterr().out


def test_compare_identical_models(tmp_path, capsys):
    """--compare toy toy: params and GFLOP ratios exactly 1, the latency
    ratio the quotient of the two medians.

    Timings are not asserted: on a shared machine the ratio of two
    millisecond forwards has been measured at 153 under load. That the
    ratio is the quotient of the two reported medians is the checkable fact.
    """
    report = _tool().main([CONFIG, '--compare', CONFIG, '--runs', '5',
                           '--warmup', '2', '--device', 'cpu',
                           '--batch-size', '2'])
    assert len(report['models']) == 2
    assert report['models'][1]['batch_size'] == 2
    assert report['ratio']['params'] == 1.0
    assert report['ratio']['gflop'] == 1.0
    medians = [m['latency_ms']['median'] for m in report['models']]
    assert report['ratio']['latency_median'] == pytest.approx(
        medians[1] / medians[0])
    assert 'ratio 2/1' in capsys.readouterr().out


def test_ratios_and_synthetic_batch_errors():
    """A zero denominator gives None; a config without shapes is named."""
    tool = _tool()
    first = dict(params=0, latency_ms=dict(median=2.0),
                 cpu_ms=dict(median=4.0), gflop=0.5, forward_memory_mb=0.5)
    second = dict(params=5, latency_ms=dict(median=3.0),
                  cpu_ms=dict(median=5.0), gflop=1.0, forward_memory_mb=4.0)
    assert tool.ratios(first, second) == dict(
        params=None, latency_median=1.5, cpu_median=1.25, gflop=2.0,
        forward_memory=None)
    cfg = tool.load_config(CONFIG, None)
    with pytest.raises(ValueError, match='declares neither'):
        tool.synthetic_batch(cfg, 1, None)
    with pytest.raises(SystemExit):
        tool.parse_args([CONFIG, '--runs', '0'])


def test_lidar_like_cloud_lies_in_range():
    """All points inside the range, on the ground (z = -1.84) or walls."""
    tool = _tool()
    gen = np.random.default_rng(0)
    pc_range = (-40.0, -40.0, -1.0 - 1.0, 40.0, 40.0, 5.4)
    points = tool.lidar_like_cloud(500, pc_range, 5, gen)
    assert points.shape == (500, 5) and points.dtype == np.float32
    assert (points[:, :3] >= np.array(pc_range[:3])).all()
    assert (points[:, :3] < np.array(pc_range[3:])).all()
    assert np.isclose(points[:, 2], -1.84, atol=1e-4).mean() > 0.2


def test_synthetic_cloud_has_one_key_frame_sweep():
    """11 sweeps of 10 points each: 10 points with lag 0 (the key frame),
    then 0.05 s steps up to 0.5 s; the batch names the time column, so
    key-frame-only steps (SDG's depth guidance) see one sweep."""
    tool = _tool()
    points = tool.with_sweep_time(np.zeros((110, 5), np.float32), 11)
    assert (points[:, 4] == 0).sum() == 10
    assert np.allclose(np.unique(points[:, 4]), 0.05 * np.arange(11))
    cfg = tool.load_config(SDG_CONFIG, None)
    batch, description = tool.synthetic_batch(cfg, 1, 220)
    assert batch['data_samples'][0].metainfo['points_time_dim'] == 4
    assert int((batch['inputs']['points'][0][:, 4] == 0).sum()) == 20
    assert '220 points in 11 sweeps' in description


def test_train_mode_steps_the_optimiser():
    """--train times ``train_step``: one call changes the toy's weights
    (SGD, lr 0.5), a prediction does not. Its GFLOP count the backward
    too: the 1x1x1 conv's 4,608 FLOP forward plus the 4,608 FLOP of its
    weight gradient (the input needs none), twice the prediction's."""
    tool = _tool()
    reports = {}
    for mode in ('predict', 'train'):
        args = tool.parse_args([CONFIG, '--device', 'cpu'] +
                               (['--train'] if mode == 'train' else []))
        subject = tool.Subject(CONFIG, None, args)
        before = [p.detach().clone() for p in subject.model.parameters()]
        subject.fresh_input()
        subject.predict()
        changed = any(not torch.equal(a, p)
                      for a, p in zip(before, subject.model.parameters()))
        assert changed == (mode == 'train')
        assert subject.model.training == (mode == 'train')
        reports[mode] = subject.static_report()
        assert reports[mode]['mode'] == mode
    assert reports['predict']['gflop'] * 1e9 == pytest.approx(4608)
    assert reports['train']['gflop'] * 1e9 == pytest.approx(2 * 4608)
    with pytest.raises(SystemExit):
        tool.parse_args([CONFIG, '--train', '--fuse-conv-bn'])


def test_synthetic_training_targets():
    """Labels: 90 % empty (index 0 of the config), every one of the 17
    classes present, int64; depth: 2 % of the pixels at 1-60 m."""
    from mmengine.config import Config
    tool = _tool()
    gen = np.random.default_rng(0)
    cfg = Config(dict(model=dict(num_classes=17, empty_index=0)))
    occ = tool.synthetic_labels((40, 40, 8), cfg, gen)
    assert occ.dtype == torch.long and occ.shape == (40, 40, 8)
    assert (occ == 0).float().mean() == pytest.approx(0.9 + 0.1 / 17,
                                                      abs=0.01)
    assert set(occ.unique().tolist()) == set(range(17))
    depth = tool.synthetic_depth(2, (30, 40), gen)
    assert depth.shape == (2, 30, 40) and depth.dtype == torch.float32
    hit = depth > 0
    assert hit.float().mean() == pytest.approx(0.02, abs=0.01)
    assert depth[hit].min() >= 1.0 and depth[hit].max() < 60.0


def test_synthetic_training_batch_has_what_the_losses_read():
    """SDG-Fusion on Occ3D (``--train --synthetic-batch``) reads its
    ``mask_camera`` (loss_mask_key) and the 2-D semantic maps: the mask is
    a bool 200 x 200 x 16 grid, about half set; ``gt_seg_2d`` has a class
    in 1..16 exactly where the depth map has a return and the ignore label
    255 elsewhere. Without labels neither is made."""
    tool = _tool()
    cfg = tool.load_config(SDG_CONFIG, None)
    batch, _ = tool.synthetic_batch(cfg, 1, 220, labels=True)
    sample = batch['data_samples'][0]
    mask = sample.mask_camera
    assert mask.dtype == torch.bool and mask.shape == (200, 200, 16)
    assert mask.float().mean() == pytest.approx(0.5, abs=0.01)
    seg, depth = sample.gt_seg_2d, sample.gt_depth
    assert seg.dtype == torch.uint8 and seg.shape == depth.shape
    hit = depth > 0
    assert ((seg != 255) == hit).all()
    assert set(seg[hit].unique().tolist()) == set(range(1, 17))
    plain, _ = tool.synthetic_batch(cfg, 1, 220)
    assert 'mask_camera' not in plain['data_samples'][0]
    assert 'gt_seg_2d' not in plain['data_samples'][0]
