"""tools/analysis_tools/robustness.py: its report on runs made up here,
and (slow tier) a whole run on the tiny world."""
import json
import math
import os.path as osp

import pytest
import torch
from mmengine.config import Config
from mmengine.registry import init_default_scope

from projects.occ_common.analysis.robustness_report import (by_condition,
                                                            load_baseline,
                                                            reported_metrics,
                                                            summarize,
                                                            write_report)
from projects.occ_common.testing.tool_logs import REPO_ROOT, load_tool

TINY = osp.join(REPO_ROOT, 'configs', 'occ_cyl',
                'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')


def _run(miou, iou=50.0, seconds=4.0):
    return dict(metrics={'occ/mIoU': miou, 'occ/IoU': iou,
                         'occ/dist_20-30m/mIoU': miou / 2,
                         'occ/rainy/mIoU': miou / 3, 'occ/car': 1.0},
                samples=2, seconds=seconds, cpu_seconds=seconds / 2)


RUNS = {
    'clean': _run(40.0),
    'lidar_missing/1': _run(20.0),
    'fog/3': _run(30.0),
    'fog/1': _run(36.0),
    'lidar_missing/3': _run(10.0),
}
RESULTS = dict(settings=dict(config='c.py', checkpoint='w.pth', subset=2,
                             seed=0, ece=False, cfg_options={}),
               runs=RUNS)


def test_runs_by_condition_in_the_tables_order():
    """Camera conditions before LiDAR ones, severities ascending."""
    conditions = by_condition(RUNS)
    assert list(conditions) == ['fog', 'lidar_missing']
    assert list(conditions['fog']) == [1, 3]


def test_reported_metrics():
    """Scored metrics, then subsets, then distance ranges; not classes."""
    assert reported_metrics(RUNS['clean']['metrics']) == [
        'occ/mIoU', 'occ/IoU', 'occ/rainy/mIoU', 'occ/dist_20-30m/mIoU']


def test_summary_and_report(tmp_path):
    """The mIoU summary is test_robustness_summary.py's hand-worked one
    (RA 0.825 / 0.375, mRA 0.6, mRR 60 %); IoU stays at 50 everywhere (RA
    1). The markdown shows them and a plot per reported metric is
    written."""
    summary = write_report(RESULTS, str(tmp_path))
    miou = summary['occ/mIoU']
    assert miou['RA'] == pytest.approx({'fog': 0.825,
                                        'lidar_missing': 0.375})
    assert miou['mRA'] == pytest.approx(0.6)
    assert miou['mRR'] == pytest.approx(60.0)
    assert summary['occ/IoU']['mRA'] == pytest.approx(1.0)
    text = (tmp_path / 'robustness.md').read_text()
    assert '| fog | camera | 36.00 | 30.00 | 0.825 | 82.5 |' in text
    assert 'mRA 0.600, mRR 60.0 %' in text
    assert '| clean | 40.00 | 50.00 | 13.33 | 20.00 | 2.00 | 1.00 |' in text
    for name in ('occ_mIoU', 'occ_IoU', 'occ_rainy_mIoU',
                 'occ_dist_20-30m_mIoU'):
        assert (tmp_path / f'{name}.png').stat().st_size > 1000


def test_baseline_gives_corruption_error(tmp_path):
    """Against itself every CE_c is 100 %; against a baseline at half the
    errors, 200 %."""
    path = tmp_path / 'base.json'
    path.write_text(json.dumps(RESULTS))
    assert summarize(RUNS, load_baseline(str(path)))['occ/mIoU']['CE'] == \
        pytest.approx({'fog': 100.0, 'lidar_missing': 100.0})
    better = {k: _run(100 - (100 - v['metrics']['occ/mIoU']) / 2)
              for k, v in RUNS.items()}
    path.write_text(json.dumps(dict(RESULTS, runs=better)))
    ce = summarize(RUNS, load_baseline(str(path)))['occ/mIoU']
    assert ce['mCE'] == pytest.approx(200.0)
    with pytest.raises(FileNotFoundError, match='baseline-json'):
        load_baseline(str(tmp_path / 'missing.json'))


def test_arguments():
    tool = load_tool('tools/analysis_tools/robustness.py')
    args = tool.parse_args(['c.py', 'w.pth', '--out', 'o', '--severities',
                            '5', '1', '5', '--conditions', 'fog', 'fog'])
    assert args.severities == [1, 5] and args.conditions == ['fog']
    assert len(tool.parse_args(['c', 'w', '--out', 'o']).conditions) == 24
    for bad in (['--severities', '6'], ['--subset', '0'],
                ['--conditions', 'hail']):
        with pytest.raises(SystemExit):
            tool.parse_args(['c', 'w', '--out', 'o', *bad])


def test_other_settings_are_not_mixed(tmp_path):
    tool = load_tool('tools/analysis_tools/robustness.py')
    path = str(tmp_path / 'robustness.json')
    with open(path, 'w') as f:
        json.dump(dict(settings=dict(seed=1), runs=RUNS), f)
    with pytest.raises(SystemExit, match='other settings'):
        tool.load_previous(path, dict(seed=0))
    assert tool.load_previous(path, dict(seed=1)) == RUNS


@pytest.fixture(scope='module')
def checkpoint(tmp_path_factory):
    """The tiny OccCylindrical's initial weights, saved."""
    cfg = Config.fromfile(TINY)
    init_default_scope('mmdet3d')
    from mmdet3d.registry import MODELS
    torch.manual_seed(0)
    model = MODELS.build(cfg.model)
    model.init_weights()
    path = str(tmp_path_factory.mktemp('ckpt') / 'tiny.pth')
    torch.save(dict(state_dict=model.state_dict(), meta={}), path)
    return path


@pytest.mark.slow
def test_whole_run_on_the_tiny_world(converted_tiny_world, checkpoint,
                                     tmp_path):
    """Clean and two conditions with the calibration error; then a second
    invocation adds a condition and keeps the first runs (their times
    unchanged); against its own results as the baseline every CE is 100 %.
    Without points the cylinder sees no LiDAR: its prediction changes."""
    tool = load_tool('tools/analysis_tools/robustness.py')
    out = str(tmp_path / 'out')
    common = [TINY, checkpoint, '--out', out, '--ece', '--cfg-options',
              f'test_dataloader.dataset.data_root={converted_tiny_world}']
    first = tool.main(common + ['--conditions', 'lidar_missing',
                                'camera_crash', '--severities', '5'])
    runs = first['runs']
    assert set(runs) == {'clean', 'lidar_missing/5', 'camera_crash/5'}
    clean = runs['clean']
    assert clean['samples'] == 2
    for key in ('occ/mIoU', 'occ/IoU', 'calib/ECE', 'calib/nonempty/ECE'):
        assert math.isfinite(clean['metrics'][key]), key
    assert runs['lidar_missing/5']['metrics'] != clean['metrics']
    ra = first['summary']['occ/IoU']['per_severity']['lidar_missing'][5]
    assert ra == pytest.approx(runs['lidar_missing/5']['metrics']['occ/IoU']
                               / clean['metrics']['occ/IoU'])
    second = tool.main(common + [
        '--conditions', 'fog', '--severities', '1', '--baseline-json',
        osp.join(out, 'robustness.json')])
    assert set(second['runs']) == set(runs) | {'fog/1'}
    assert second['runs']['clean']['seconds'] == clean['seconds']
    assert second['summary']['occ/mIoU']['CE'] == pytest.approx(
        {'lidar_missing': 100.0, 'camera_crash': 100.0})
    text = open(osp.join(out, 'robustness.md')).read()
    assert 'lidar_missing' in text and 'CE_c' in text
