"""tools/analysis_tools/check_dataset.py on the real nuScenes key frame and
on a broken synthetic world, in-process.

The real frame (``../shared``; skipped where absent) has no labels, no
sweeps and no previous key frame: its label checks are skipped and the
label-free ones pass. Its numbers, measured when this was written
(2026-11), are the reference values docs/customize_dataset.md quotes:
the five overlapping camera pairs agree at rank correlation 0.71-0.96,
the reflectivity edges land on image edges 1.14-1.65 times as often as
by chance, and every ``lidar2cam`` is within 0.07 deg / 0.4 m of the one
the mounts give (the car moves between the LiDAR's and a camera's
capture).
"""
import json
import os
import os.path as osp

import pytest

from projects.occ_common.analysis.real_sample import (INFO_FILE,
                                                      MISSING_REASON,
                                                      real_sample_dir)
from projects.occ_common.testing import broken_worlds
from projects.occ_common.testing.tool_logs import (REPO_ROOT, load_tool,
                                                   run_create_data)

TOOL = 'tools/analysis_tools/check_dataset.py'
PAPER = osp.join(REPO_ROOT, 'configs', 'occ_cyl',
                 'occcyl_r50-swins_3xb1-24e_surroundocc-nus.py')
TINY = osp.join(REPO_ROOT, 'configs', 'occ_cyl',
                'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')


@pytest.fixture(scope='module')
def real_info(tmp_path_factory):
    if real_sample_dir() is None:
        pytest.skip(MISSING_REASON)
    out = str(tmp_path_factory.mktemp('real_info'))
    with pytest.warns(UserWarning):
        written = run_create_data(
            '--root-path', real_sample_dir(), '--out-dir', out,
            '--from-mmdet3d-info', osp.join(real_sample_dir(), INFO_FILE))
    return next(iter(written.values()))


def test_real_sample_passes_the_label_free_checks(real_info, tmp_path):
    """A paper config on the real key frame: calibration, label grid and
    sequence pass; labels, masks and the class histogram have nothing to
    check; the report, its JSON and two pictures are written."""
    tool = load_tool(TOOL)
    out = str(tmp_path / 'report')
    report = tool.main([PAPER, '--data-root', real_sample_dir(), '--out',
                        out, '--pictures', '1', '--cfg-options',
                        f'test_dataloader.dataset.ann_file={real_info}'])
    verdicts = {c: s.verdict for c, s in report.summaries.items()}
    assert verdicts == dict(calibration='pass', labels_vs_lidar='skip',
                            label_grid='pass', masks='skip',
                            sequence='pass', class_histogram='skip')
    assert tool.exit_status(report) == 0
    numbers = report.summaries['calibration'].numbers
    overlaps = {k: v['mean'] for k, v in numbers.items()
                if k.endswith('.overlap_consistency')}
    assert len(overlaps) == 5 and min(overlaps.values()) > 0.65
    alignment = [v['mean'] for k, v in numbers.items()
                 if k.endswith('.edge_alignment')]
    assert len(alignment) == 6 and min(alignment) > 1.1
    assert max(v['mean'] for k, v in numbers.items()
               if k.endswith('.extrinsic_deg')) < 0.1
    assert sorted(os.listdir(out)) == ['pictures', 'report.json',
                                       'report.md']
    assert len(report.pictures) == 2
    with open(osp.join(out, 'report.md')) as f:
        markdown = f.read()
    assert '**Verdict: PASS**' in markdown
    assert '| calibration | **pass** | 0 / 1 / 0 / 0 |' in markdown
    with open(osp.join(out, 'report.json')) as f:
        saved = json.load(f)
    assert saved['verdict'] == 'pass'
    assert saved['samples'][0]['token'] == 'ca9a282c9e77460f8360f564131a8af5'


def test_real_images_swapped_fail_the_calibration(real_info):
    """The real frame with CAM_FRONT's and CAM_BACK's images exchanged:
    the pairs with either camera disagree (rank correlation -0.69 for
    CAM_FRONT|CAM_FRONT_RIGHT, -0.34 for the two others, measured), the
    pairs of the other cameras still agree (0.71, 0.78)."""
    from mmengine.config import Config
    from mmengine.registry import DATASETS, init_default_scope

    from projects.occ_common.analysis.dataset_doctor.calibration import \
        check_calibration
    from projects.occ_common.analysis.dataset_doctor.sample_data import \
        load_sample
    cfg = Config.fromfile(PAPER)
    init_default_scope('mmdet3d')
    dataset = DATASETS.build(dict(cfg.test_dataloader.dataset,
                                  data_root=real_sample_dir(),
                                  ann_file=real_info))
    sample = load_sample(dataset, 0, ego_box=cfg.ego_box)
    front, back = sample.cameras[0], sample.cameras[3]
    assert (front.name, back.name) == ('CAM_FRONT', 'CAM_BACK')
    front.image, back.image = back.image, front.image
    result = check_calibration(sample)
    assert result.verdict == 'fail'
    pairs = {k[:-len('.overlap_consistency')]: v
             for k, v in result.numbers.items()
             if k.endswith('.overlap_consistency')}
    assert pairs['CAM_FRONT|CAM_FRONT_RIGHT'] < 0
    assert pairs['CAM_FRONT|CAM_FRONT_LEFT'] < 0.4
    assert pairs['CAM_BACK|CAM_BACK_RIGHT'] < 0.4
    assert pairs['CAM_FRONT_LEFT|CAM_BACK_LEFT'] > 0.6
    assert pairs['CAM_FRONT_RIGHT|CAM_BACK_RIGHT'] > 0.6


def test_a_failing_check_sets_the_exit_status(world_copy, tmp_path):
    """A missing sweep: the sequence check fails and names the file, the
    tool's exit status is 1; --samples 1 checks the first sample only
    (the one whose sweep is gone)."""
    path = broken_worlds.missing_sweep(world_copy)
    tool = load_tool(TOOL)
    report = tool.main([TINY, '--data-root', world_copy, '--out',
                        str(tmp_path / 'out'), '--samples', '1',
                        '--pictures', '0'])
    assert len(report.tokens) == 1
    assert report.summaries['sequence'].verdict == 'fail'
    assert any(path in sentence for _, _, sentence in
               report.summaries['sequence'].findings)
    assert tool.exit_status(report) == 1
