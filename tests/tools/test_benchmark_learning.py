"""tools/analysis_tools/benchmark_learning.py: budget rewrite, resume, time
limit, reuse.

The training runs use the toy config (tests/data/configs/toy_occ.py: 8
training samples in batches of 2, so 4 iterations per epoch) in child
processes, exactly as the benchmark starts them.
"""
import argparse
import glob
import json
import os.path as osp
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from mmengine.config import Config, DictAction

from projects.occ_common.analysis import tool_runs
from projects.occ_common.evaluation import (read_confusion_csv,
                                            write_confusion_csv)
from projects.occ_common.testing.tool_logs import load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


def _tool():
    return load_tool('tools/analysis_tools/benchmark_learning.py')


def _epoch_cfg():
    return Config(dict(
        train_cfg=dict(type='EpochBasedTrainLoop', max_epochs=12,
                       val_interval=1),
        param_scheduler=[
            dict(type='LinearLR', start_factor=0.1, by_epoch=False,
                 begin=0, end=20),
            dict(type='MultiStepLR', by_epoch=True, milestones=[8, 11]),
            dict(type='CosineAnnealingLR', T_max=12, begin=0, end=12,
                 convert_to_iter_based=True),
        ],
        default_hooks=dict(checkpoint=dict(type='CheckpointHook',
                                           interval=1),
                           logger=dict(type='LoggerHook', interval=50)),
        log_processor=dict(type='LogProcessor', window_size=50,
                           by_epoch=True)))


def test_budget_stretches_schedule():
    """12 epochs x 10 iterations = 120 planned; a budget of 60 halves
    every position: warm-up end 20 it -> 10; milestones 8, 11 epochs = 80,
    110 it -> 40, 55; cosine T_max = end = 12 epochs = 120 it -> 60."""
    cfg = _epoch_cfg()
    assert _tool().set_iteration_budget(cfg, 60, 15, 10, 5) == 60
    assert cfg.train_cfg == dict(type='IterBasedTrainLoop', max_iters=60,
                                 val_interval=15)
    warmup, steps, cosine = cfg.param_scheduler
    assert (warmup['begin'], warmup['end']) == (0, 10)
    assert steps['milestones'] == [40, 55]
    assert (cosine['T_max'], cosine['begin'], cosine['end']) == (60, 0, 60)
    assert 'convert_to_iter_based' not in cosine
    assert all(s['by_epoch'] is False for s in cfg.param_scheduler)
    ckpt = cfg.default_hooks.checkpoint
    assert (ckpt.interval, ckpt.by_epoch, ckpt.save_last) == (15, False,
                                                              True)
    assert cfg.default_hooks.logger.log_metric_by_epoch is False
    assert cfg.log_processor.window_size == 5


def test_budget_none_keeps_length():
    """No budget: 12 epochs x 10 = 120 iterations, positions unscaled."""
    cfg = _epoch_cfg()
    assert _tool().set_iteration_budget(cfg, None, 30, 10, 10) == 120
    assert cfg.param_scheduler[1]['milestones'] == [80, 110]


def _spec(work_dir, iters, max_minutes=None, max_cpu_minutes=None):
    return dict(config=CONFIG, options=[], iters=iters, val_interval=3,
                max_minutes=max_minutes, max_cpu_minutes=max_cpu_minutes,
                log_interval=1, work_dir=work_dir)


def _train(spec):
    proc = subprocess.run(
        [sys.executable,
         osp.join(ROOT, 'tools', 'analysis_tools', 'benchmark_learning.py'),
         '--train-one', json.dumps(spec)], cwd=ROOT, capture_output=True,
        text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    with open(osp.join(spec['work_dir'], 'train_clock.json')) as f:
        return json.load(f)


@pytest.mark.slow
def test_resume_continues_curves_and_clock(tmp_path):
    """A run of 6 iterations stopped at iteration 1 (a CPU-time limit of
    60 ns stands in for a kill after the first checkpoint), then the same
    run without the limit resumes at iteration 1 with the same schedule
    (tools/train.py refuses a resume whose schedule differs from the
    checkpoint's): one loss point per iteration (log interval 1),
    validation of the untrained model (0), at the stop (1), at 3 and 6,
    and the training time of both segments adds up."""
    work = str(tmp_path / 'train')
    first = _train(_spec(work, 6, max_cpu_minutes=1e-9))
    assert (first['iterations'], first['stopped_by_time']) == (1, True)
    second = _train(_spec(work, 6))
    assert (second['iterations'], second['stopped_by_time']) == (6, False)
    assert second['train_seconds'] > first['train_seconds'] > 0
    curves = _tool().read_curves(work)
    assert [s for s, _ in curves['loss']] == [1, 2, 3, 4, 5, 6]
    assert [s for s, _ in curves['val']] == [0, 1, 3, 6]
    assert 'occ/mIoU' in curves['val'][-1][1]


@pytest.mark.slow
@pytest.mark.parametrize('limit', ['max_minutes', 'max_cpu_minutes'])
def test_time_limit_stops_and_validates(tmp_path, limit):
    """A limit of 60 ns (wall or CPU time) is reached in the first
    iteration however fast the machine (a toy iteration can take under the
    6 ms once used here): training ends there, iteration 1 is checkpointed
    (save_last) and validated."""
    work = str(tmp_path / 'train')
    clock = _train(_spec(work, 6, **{limit: 1e-9}))
    assert (clock['iterations'], clock['stopped_by_time']) == (1, True)
    assert osp.isfile(osp.join(work, 'iter_1.pth'))
    assert [s for s, _ in _tool().read_curves(work)['val']] == [0, 1]


@pytest.mark.slow
def test_bench_run_writes_row_and_reuses_it(tmp_path, capsys):
    """A full run (train, test, curve) and its reuse; other settings for
    the same run folder are refused."""
    tool = _tool()
    args = SimpleNamespace(iters=4, val_interval=2, max_minutes=None,
                           log_interval=1, pictures=0, val_scenes=1,
                           samples=4)
    log = str(tmp_path / 'log.txt')
    row = tool.bench_run('toy', CONFIG, [], args, None, str(tmp_path), log)
    assert row['iterations'] == 4 and row['epoch_length'] == 4
    assert row['labels'] == 'SurroundOcc'
    assert [s for s, _ in row['curves']['val']] == [0, 2, 4]
    # The test of the last checkpoint and the last validation agree.
    assert row['metrics']['occ/mIoU'] == pytest.approx(
        row['curves']['val'][-1][1]['occ/mIoU'], abs=1e-3)
    assert osp.getsize(row['curve_png']) > 1000
    again = tool.bench_run('toy', CONFIG, [], args, None, str(tmp_path), log)
    assert 'reusing' in capsys.readouterr().out
    assert again['metrics'] == row['metrics']
    # --retest: no training, a second test of the same checkpoint (a new
    # log folder) with the same metrics, GT voxel counts included.
    tests = glob.glob(str(tmp_path / 'runs' / 'toy' / 'test' / '*' / '*.json'))
    args.retest = True
    retested = tool.bench_run('toy', CONFIG, [], args, None, str(tmp_path),
                              log)
    out = capsys.readouterr().out
    assert 'reusing' not in out and '--train-one' not in out
    assert len(glob.glob(
        str(tmp_path / 'runs' / 'toy' / 'test' / '*' / '*.json'))) == len(
            tests) + 1
    assert {k: v for k, v in retested['metrics'].items()
            if k.startswith('occ/')} == {
                k: v for k, v in row['metrics'].items()
                if k.startswith('occ/')}
    # The counts reach the json log as numbers (an int became null there),
    # and they add up to the 8 x 8 x 4 voxels of each of the 4 samples
    # that are not ignored.
    counts = [v for k, v in row['metrics'].items()
              if k.startswith('occ/gt_voxels/')]
    assert counts and all(isinstance(v, float) for v in counts)
    assert 0 < sum(counts) <= 4 * 8 * 8 * 4
    # The test's confusion matrix: its rows add up to the same counts.
    names, confusion = read_confusion_csv(row['confusion_csv'])
    assert {f'occ/gt_voxels/{n}': float(c)
            for n, c in zip(names, confusion.sum(1))} == {
                k: v for k, v in row['metrics'].items()
                if k.startswith('occ/gt_voxels/')}
    assert retested['iterations'] == 4
    args.retest = False
    args.iters = 8
    with pytest.raises(SystemExit, match='other settings'):
        tool.bench_run('toy', CONFIG, [], args, None, str(tmp_path), log)


@pytest.mark.slow
def test_extend_continues_a_time_stopped_run(tmp_path, capsys):
    """A 4-iteration run stopped after iteration 1 by a 60 ns CPU budget;
    with --extend and no budget it trains on to iteration 4 (validations
    at 0, 1 (the stop), 2 and 4) and the stopped row stays as
    result-1it.json. Before, the new budget was refused as "other
    settings". Another --iters is still refused, and so is extending a run
    that ended its schedule."""
    tool = _tool()
    args = SimpleNamespace(iters=4, val_interval=2, max_minutes=None,
                           max_cpu_minutes=1e-9, log_interval=1, pictures=0,
                           val_scenes=1, samples=4, extend=False)
    log = str(tmp_path / 'log.txt')
    stopped = tool.bench_run('toy', CONFIG, [], args, None, str(tmp_path),
                             log)
    assert (stopped['iterations'], stopped['stopped_by_time']) == (1, True)
    args.max_cpu_minutes = None
    with pytest.raises(SystemExit, match='other settings'):
        tool.bench_run('toy', CONFIG, [], args, None, str(tmp_path), log)
    args.extend, args.iters = True, 8
    with pytest.raises(SystemExit, match='larger --max-minutes'):
        tool.bench_run('toy', CONFIG, [], args, None, str(tmp_path), log)
    args.iters = 4
    row = tool.bench_run('toy', CONFIG, [], args, None, str(tmp_path), log)
    assert 'kept as result-1it.json' in capsys.readouterr().out
    assert (row['iterations'], row['stopped_by_time']) == (4, False)
    assert [s for s, _ in row['curves']['val']] == [0, 1, 2, 4]
    with open(tmp_path / 'runs' / 'toy' / 'result-1it.json') as f:
        assert json.load(f)['iterations'] == 1
    assert 'max_cpu_minutes' not in row['settings']  # no budget now


def test_extend_takes_only_larger_budgets_of_time_stopped_runs(tmp_path):
    """Budgets may grow (1 -> 2 CPU-min) or go (1 -> none); a smaller one
    (2 -> 1), a new one on an unlimited run (none -> 1) or any other
    setting (iters 4 -> 8) is not an extension. A run that ended its
    schedule is refused and its result stays where it was."""
    grows = _tool()._budget_grows
    base = dict(config='c', iters=4, max_minutes=None)
    assert grows(dict(base, max_cpu_minutes=1), dict(base, max_cpu_minutes=2))
    assert grows(dict(base, max_cpu_minutes=1), base)
    assert not grows(dict(base, max_cpu_minutes=2),
                     dict(base, max_cpu_minutes=1))
    assert not grows(base, dict(base, max_cpu_minutes=1))
    assert not grows(dict(base, max_cpu_minutes=1),
                     dict(base, iters=8, max_cpu_minutes=2))
    result = tmp_path / 'result.json'
    result.write_text(json.dumps(dict(iterations=4, stopped_by_time=False)))
    with pytest.raises(SystemExit, match=r'whole schedule \(4 iterations'):
        _tool()._keep_stopped_result(str(tmp_path))
    assert result.is_file()


def test_world_with_other_parameters_is_refused(tmp_path):
    """A synthetic world of 3 scenes is not silently reused for 10."""
    meta = tmp_path / 'synthetic_gt' / 'meta.json'
    meta.parent.mkdir()
    meta.write_text(json.dumps(dict(complete=True, parameters=dict(
        num_scenes=3, samples_per_scene=8, seed=0))))
    with pytest.raises(SystemExit, match='num_scenes'):
        tool_runs.prepare_world(str(tmp_path), str(tmp_path / 'l'),
                                scenes=10, samples=8)


def test_format_table_extra_lines():
    """Rows become columns; extra lines follow the mIoU."""
    rows = [dict(name='a', labels='Occ3D', train_s=90.0,
                 metrics={'occ/IoU': 50.0, 'occ/mIoU': 12.345,
                          'occ/car': float('nan')}, iterations=7)]
    table = tool_runs.format_table(
        rows, [('iterations', lambda r: str(r['iterations']))])
    assert table.splitlines() == [
        '| | a |', '|---|---|', '| labels | Occ3D |',
        '| train time | 1.5 min |', '| IoU | 50.00 |',
        '| **mIoU** | 12.35 |', '| iterations | 7 |', '| car | n/a |']


def test_ray_iou_gets_one_line_and_no_class_lines():
    """RayIoUMetric's keys (occ/RayIoU, @1/@2/@4 and per class) make one
    line, 'mean (@1 / @2 / @4)', after the mIoU; a row without RayIoU
    reads n/a there; the per-class RayIoU keys are not class lines."""
    ray = {'occ/RayIoU': 30.0, 'occ/RayIoU@1': 20.0, 'occ/RayIoU@2': 30.0,
           'occ/RayIoU@4': 40.0, 'occ/RayIoU/car': 7.0,
           'occ/RayIoU@1/car': 5.0}
    rows = [dict(name='a', labels='Occ3D, no mask', train_s=60.0,
                 metrics={'occ/IoU': 50.0, 'occ/mIoU': 12.0,
                          'occ/car': 3.0, **ray}),
            dict(name='b', labels='Occ3D', train_s=60.0,
                 metrics={'occ/IoU': 40.0, 'occ/mIoU': 10.0,
                          'occ/car': 2.0})]
    assert tool_runs.class_keys(rows) == ['car']
    assert tool_runs.format_table(rows).splitlines()[6:] == [
        '| RayIoU (@1 / @2 / @4 m) | 30.00 (20.00 / 30.00 / 40.00) | n/a |',
        '| car | 3.00 | 2.00 |']


def test_class_lines_show_gt_voxels_and_weak_large_classes():
    """With the metric's GT counts a class cell reads 'IoU (GT voxels)';
    the large-class line names the classes of >= 1,000 GT voxels at IoU
    <= 10: car (5.00, 2,000 voxels) but neither bus (60.00) nor bicycle
    (0.00, only 999 voxels) nor free (the IoU line's business)."""
    metrics = {'occ/IoU': 50.0, 'occ/mIoU': 20.0, 'occ/car': 5.0,
               'occ/bus': 60.0, 'occ/bicycle': 0.0, 'occ/free': 90.0,
               'occ/gt_voxels/car': 2000, 'occ/gt_voxels/bus': 1000,
               'occ/gt_voxels/bicycle': 999, 'occ/gt_voxels/free': 10**6}
    row = dict(name='a', labels='Occ3D', train_s=60.0, metrics=metrics)
    table = tool_runs.format_table([row])
    assert '| car | 5.00 (2,000) |' in table.splitlines()
    assert '| bicycle | 0.00 (999) |' in table.splitlines()
    assert _tool()._weak_large_classes(row) == 'car'
    metrics['occ/car'] = 10.5
    assert _tool()._weak_large_classes(row) == 'none'
    del metrics['occ/gt_voxels/car']
    assert tool_runs.large_classes(metrics) == ['bus']
    row['metrics'] = {'occ/mIoU': 1.0}
    assert _tool()._weak_large_classes(row) == 'n/a'
    # A result logged while the counts were ints holds them as null: no
    # counts, and the table of such a row still renders.
    row['metrics'] = {'occ/mIoU': 1.0, 'occ/car': 5.0,
                      'occ/gt_voxels/car': None}
    assert _tool()._weak_large_classes(row) == 'n/a'
    assert '| car | 5.00 |' in tool_runs.format_table([row]).splitlines()


def test_weak_classes_name_where_their_voxels_went(tmp_path):
    """car (IoU 5, 2,000 GT voxels) is weak; of its row (100, 20, 1,880,
    0): bus takes 1,880 / 2,000 = 94 %, empty 100 / 2,000 = 5 %. A row
    without a CSV reads 'n/a'; one without weak classes 'none'."""
    names = ('empty', 'car', 'bus', 'bicycle')
    path = str(tmp_path / 'confusion.csv')
    write_confusion_csv(path, np.array([[9000, 0, 0, 0], [100, 20, 1880, 0],
                                        [0, 0, 1000, 0], [0, 0, 0, 0]]),
                        names)
    metrics = {'occ/car': 5.0, 'occ/bus': 60.0, 'occ/gt_voxels/car': 2000,
               'occ/gt_voxels/bus': 1000, 'occ/gt_voxels/bicycle': 0,
               'occ/gt_voxels/empty': 9000}
    row = dict(metrics=metrics, confusion_csv=path)
    assert _tool()._weak_class_confusions(row) == 'car: bus 94 %, empty 5 %'
    row['confusion_csv'] = str(tmp_path / 'missing.csv')
    assert _tool()._weak_class_confusions(row) == 'n/a'
    metrics['occ/car'] = 50.0
    assert _tool()._weak_class_confusions(row) == 'none'


_CAMERA_OFF = dict(lidar_encoder=None, fusion=None, loss_seg=None)


@pytest.mark.parametrize('name, expect', [
    ('occcyl-tiny-nodepthsup', dict(loss_depth=None)),
    ('occcyl-small-nodepthsup', dict(loss_depth=None)),
    ('occcyl-small-seg2d-nodepthsup', dict(loss_depth=None)),
    ('occcyl-small-cyl128',
     dict(cylinder=dict(shape=[128, 256, 16], radius='inscribed',
                        clamp=True))),
    ('sdg-camera-lss-tiny', _CAMERA_OFF),
    ('sdg-camera-lss-small', _CAMERA_OFF),
    ('sdg-camera-sdg-small',
     dict(lidar_encoder=None, fusion=None)),
    ('sdg-kl-small-sharedhead', dict(kl_losses='three_loss')),
    ('sdg-kl-small-sharedhead-detachcam',
     dict(kl_losses='three_loss', detach_teacher_camera=True)),
    ('sdg-kl-small-threeloss',
     dict(kl_losses='three_loss', separate_teacher_head=True)),
    ('sdg-kl-small-norm',
     dict(loss_distill=dict(type='FOADDistillLoss', alpha=1.0, beta=1.0,
                            loss_weight=1.0, normalize='channel'))),
])
def test_ablation_runs_switch_their_module_off(name, expect):
    """Each named ablation run is its base config with only the named
    modules switched off (or, for cyl128, the cylinder's shape changed
    while its radius fit and clamping stay): the options merge into a
    config whose model has those entries None (the camera variant, the
    new cylinder), while the base run's has them set."""

    tool = _tool()
    config, options = tool.RUNS[name]
    cfg = Config.fromfile(osp.join(ROOT, config))
    parser = argparse.ArgumentParser()
    parser.add_argument('--o', nargs='+', action=DictAction)
    cfg.merge_from_dict(parser.parse_args(['--o', *options]).o)
    base = Config.fromfile(osp.join(ROOT, config))
    for key, value in expect.items():
        assert cfg.model[key] == value
        assert base.model.get(key) != value


def test_rot90_run_turns_only_the_training_scenes():
    """``occcyl-small-seg2d-nodepthsup-rot90`` is the run without depth
    supervision plus one option, and that option lands on the training
    pipeline's OccBEVAug (a list index: the test fails if the pipeline's
    order moves it) with its flips still off; validation and test keep
    their identity BEV transform."""
    tool = _tool()
    config, options = tool.RUNS['occcyl-small-seg2d-nodepthsup-rot90']
    base_config, base_options = tool.RUNS['occcyl-small-seg2d-nodepthsup']
    assert config == base_config
    assert options[:len(base_options)] == base_options
    cfg = Config.fromfile(osp.join(ROOT, config))
    parser = argparse.ArgumentParser()
    parser.add_argument('--o', nargs='+', action=DictAction)
    cfg.merge_from_dict(parser.parse_args(['--o', *options]).o)
    bev = [t for t in cfg.train_dataloader.dataset.pipeline
           if t['type'] == 'OccBEVAug']
    assert bev == [dict(type='OccBEVAug', flip_x_prob=0.0, flip_y_prob=0.0,
                        rot90=True)]
    for loader in ('val_dataloader', 'test_dataloader'):
        bev = [t for t in cfg[loader].dataset.pipeline
               if t['type'] == 'OccBEVAug']
        assert bev == [dict(type='OccBEVAug', test_mode=True)]


@pytest.mark.parametrize('argv', [
    ['--runs', 'occcyl-small', '--suffix', '-bs4'],
    ['--suffix', '-bs4', '--runs', 'occcyl-small'],
    ['--runs', 'occcyl-small', '--suffix=-bs4'],
])
def test_suffix_may_start_with_a_dash(argv):
    """``--suffix -bs4`` names the runs ``occcyl-small-bs4``: argparse alone
    reads ``-bs4`` as an unknown option and exits ("expected one
    argument"); the ``=`` form keeps working."""
    args = _tool().parse_args(argv)
    assert args.suffix == '-bs4'
    assert args.runs == ['occcyl-small']


def test_suffix_does_not_swallow_the_next_option(capsys):
    """``--suffix --retest`` (the suffix forgotten) is refused as before
    rather than naming the runs ``occcyl-small--retest`` and dropping
    ``--retest``."""
    with pytest.raises(SystemExit):
        _tool().parse_args(['--runs', 'occcyl-small', '--suffix', '--retest'])
    assert 'expected one argument' in capsys.readouterr().err


def test_no_mask_configs_point_their_evaluators_and_name_their_labels():
    """The small SDG-Fusion scored with RayIoU: data_options also points
    its RayIoU metric (evaluator 1 of the list, which reads the info file
    itself) at the world; the OccupancyMetric the table reads is
    evaluator 0 there and the single evaluator of the masked config; the
    labels say whether the loss saw every voxel."""
    nomask, masked = (osp.join(
        ROOT, 'configs', 'sdg_occ',
        f'sdgocc-fusion_small_1xb1-20e_occ3d-nus{tag}-synthetic.py')
        for tag in ('-nomask', ''))
    options = tool_runs.data_options('/w', nomask)
    assert options[3:] == ['val_evaluator.1.data_root=/w/',
                           'test_evaluator.1.data_root=/w/']
    assert len(tool_runs.data_options('/w', masked)) == 3
    cfg_nomask, cfg_masked = Config.fromfile(nomask), Config.fromfile(masked)
    assert tool_runs.occupancy_metric(cfg_nomask, 'test')[0] == \
        'test_evaluator.0'
    assert tool_runs.occupancy_metric(cfg_masked, 'test')[0] == \
        'test_evaluator'
    assert _tool()._labels(cfg_nomask) == 'Occ3D, no mask'
    assert _tool()._labels(cfg_masked) == 'Occ3D'
