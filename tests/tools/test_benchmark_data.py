"""tools/analysis_tools/benchmark_data.py --real-sample: what it times.

The real nuScenes key frame of ``../shared`` goes through a paper config's
training pipeline with the tool's stand-ins (the key frame as its 10
sweeps, an all-empty label grid, one lidarseg label per point). Timings
are not asserted, only what they are made of: on a shared 2-core machine
they vary by tens of percent.
"""
import json
import os.path as osp

import pytest
import torch

from projects.occ_common.analysis.real_sample import (INFO_FILE,
                                                      MISSING_REASON,
                                                      real_sample_dir)
from projects.occ_common.testing.tool_logs import load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SDG = osp.join(ROOT, 'configs', 'sdg_occ',
               'sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py')
SDG_2F = osp.join(ROOT, 'configs', 'sdg_occ',
                  'sdgocc-fusion-2f_r50_4xb2-24e_occ3d-nus.py')
#: SDG-Fusion's training steps, in pipeline order.
SDG_STEPS = {
    'get_data_info', 'LoadOccPointsFromFile', 'LoadLidarSegLabels',
    'RemoveEgoPoints', 'LoadOccPointsFromMultiSweeps',
    'LoadMultiViewImagesOcc', 'MultiViewImageAug', 'LoadOccupancyGT',
    'PointsToEgoFrame', 'OccBEVAug', 'PointsToDepthMaps',
    'PointsToSemanticMaps', 'PointsRangeFilter', 'PackOccInputs'
}


def _tool():
    return load_tool('tools/analysis_tools/benchmark_data.py')


def test_missing_real_sample_is_a_skip_with_its_reason(tmp_path, capsys):
    """A folder without the sample's info file: nothing is built or timed,
    and the report (and the printout) names the folder and the file."""
    absent = str(tmp_path / 'absent')
    report = _tool().main(['--real-sample', absent, '--config', SDG])
    assert set(report) == {'sample_dir', 'skipped'}
    assert report['sample_dir'] == absent
    assert INFO_FILE in report['skipped'] and absent in report['skipped']
    assert capsys.readouterr().out.startswith('skipped: no real nuScenes')


def test_arguments_are_checked():
    """Several configs only with --real-sample, which builds its own data
    root; at least one sample and one round."""
    tool = _tool()
    for argv in (['--config', SDG, SDG_2F],
                 ['--real-sample', '--data-root', 'data/nuscenes'],
                 ['--real-sample', '--num-samples', '0'],
                 ['--real-sample', '--rounds', '0']):
        with pytest.raises(SystemExit):
            tool.parse_args(argv)
    args = tool.parse_args(['--real-sample'])
    assert args.real_sample == '' and args.rounds == 3
    assert args.num_samples >= 10


@pytest.mark.skipif(real_sample_dir() is None, reason=MISSING_REASON)
@pytest.mark.filterwarnings('ignore:.*scene unknown')
def test_real_sample_times_every_step_of_the_train_pipeline(tmp_path):
    """SDG-Fusion, 2 rounds of 2 samples: 4 samples timed, per-step means
    that add up to the mean total (each step is timed from the end of the
    one before), CPU time measured, and this process's torch threads as
    they were; the two-frame config is skipped (the
    sample has no previous key frame).

    The packed sample is the config's: six 256x704 views, and 11 copies
    (the key frame and its 10 stand-in sweeps) of the 23,783 key-frame
    points left after the car (8,526 of 34,688) and the range filter:
    261,613 points."""
    out = tmp_path / 'real.json'
    threads = torch.get_num_threads()
    report = _tool().main([
        '--real-sample', '--config', SDG, SDG_2F, '--num-samples', '2',
        '--rounds', '2', '--out', str(out)
    ])
    assert json.loads(out.read_text()) == report
    assert torch.get_num_threads() == threads  # restored
    assert report['torch_threads'] == 1 and len(report['stand_ins']) == 4
    skipped = report['configs'][SDG_2F]
    assert skipped == dict(skipped='num_frames=2: the real sample has no '
                           'previous key frame')
    timed = report['configs'][SDG]
    assert timed['samples'] == 4 and len(timed['wall_s']['runs']) == 4
    assert len(timed['round_median_wall_s']) == 2
    for key in ('wall_s', 'cpu_s'):
        stats = timed[key]
        assert 0 < stats['min'] <= stats['median'] <= stats['max']
    assert set(timed['steps']) == SDG_STEPS
    mean_wall = sum(timed['wall_s']['runs']) / 4
    assert sum(s['wall_s'] for s in timed['steps'].values()) == \
        pytest.approx(mean_wall, rel=1e-6)
    walls = [s['wall_s'] for s in timed['steps'].values()]
    assert walls == sorted(walls, reverse=True)
    assert timed['img_input'] == [6, 3, 256, 704]
    assert timed['points'] == 11 * 23783 == 261613
