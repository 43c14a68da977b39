"""The doctor catches the data bugs: each broken copy of the tiny synthetic
world fails, naming the check, while the untouched world passes.

The world is the ``converted_tiny_world`` of tests/conftest.py (one scene
of two key frames, 160x90 images, 80 azimuth steps), damaged in a private
copy per case by :mod:`projects.occ_common.testing.broken_worlds`; the
configs are the tiny ones of each label format (SurroundOcc: LiDAR frame,
Occ3D: ego frame). What is asserted: the split's verdict is ``fail``, the
failing checks are exactly the one the bug belongs to, and its finding
names what is wrong (the other reading of the grid that fits, the camera
pair, the file), with the numbers that were measured when this was
written (2026-11) as bounds.
"""
import os.path as osp

import pytest
from mmengine.config import Config

from projects.occ_common.analysis.dataset_doctor import (CHECKS, FAIL,
                                                         run_doctor)
from projects.occ_common.testing import broken_worlds
from projects.occ_common.testing.tool_logs import REPO_ROOT

CONFIGS = dict(
    surroundocc=osp.join(REPO_ROOT, 'configs', 'occ_cyl',
                         'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py'),
    occ3d=osp.join(REPO_ROOT, 'configs', 'sdg_occ',
                   'sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py'))


def _doctor(root, occ_format='surroundocc'):
    return run_doctor(Config.fromfile(CONFIGS[occ_format]), 'val',
                      data_root=root)


def _failing(report):
    return {c for c in CHECKS if report.summaries[c].verdict == FAIL}


def _sentences(report, check):
    return ' '.join(s for _, _, s in report.summaries[check].findings)


@pytest.mark.parametrize('occ_format', sorted(CONFIGS))
def test_untouched_world_passes(converted_tiny_world, occ_format):
    """Every check passes or has nothing to check (SurroundOcc has no
    masks); the labels hold nearly every point (0.98-1.00 measured), no
    other reading of the grid explains them better, the overlapping
    cameras agree (rank correlation 0.7-0.9 measured), Occ3D's masks fit
    the points and the rig, the sweeps are
    0.05 s apart and the classes' shares are within 0.2 (total variation;
    0.06 / 0.14 measured for SurroundOcc / Occ3D: one scene against the
    reference's two) of the synthetic reference."""
    report = _doctor(converted_tiny_world, occ_format)
    assert report.verdict == 'pass', [
        s.findings for s in report.summaries.values() if s.findings]
    assert len(report.tokens) == 2
    numbers = report.summaries['labels_vs_lidar'].numbers
    assert numbers['hit']['min'] > 0.95
    assert numbers['best_other.gain']['max'] < 0.05
    calibration = report.summaries['calibration'].numbers
    overlaps = [v['min'] for k, v in calibration.items()
                if k.endswith('.overlap_consistency')]
    assert overlaps and min(overlaps) > 0.6
    assert max(v['max'] for k, v in calibration.items()
               if k.endswith('.extrinsic_deg')) < 1e-3
    sequence = report.summaries['sequence'].numbers
    # Timestamps of ~1.5e9 s carry float64 steps of ~2e-7 s.
    gap = sequence['max_sweep_gap_s']['max']
    assert gap == pytest.approx(0.05, abs=1e-6)
    assert sequence['sweep_pose_error_m']['max'] < 1e-3
    assert report.summaries['class_histogram'].numbers['distance'][
        'mean'] < 0.2
    masks = report.summaries['masks']
    if occ_format == 'surroundocc':
        assert masks.verdict == 'skip'
    else:
        # The generator traces mask_lidar from the same rays (1.00) and
        # mask_camera from the same rig (0.99 measured).
        assert masks.verdict == 'pass'
        assert masks.numbers['points_in_lidar_mask']['min'] == 1.0
        assert masks.numbers['camera_mask_in_view']['min'] > 0.95


@pytest.mark.parametrize('damage, check, named', [
    (lambda root: broken_worlds.labels_in_other_frame(root, 'surroundocc'),
     'labels_vs_lidar', 'in the ego frame'),
    (lambda root: broken_worlds.shifted_labels(root, 'surroundocc'),
     'labels_vs_lidar', 'shifted by (2, 0,'),
    (lambda root: broken_worlds.flipped_labels(root, 'surroundocc'),
     'labels_vs_lidar', 'flipped along y'),
    (lambda root: broken_worlds.labels_with_voxel_size(root, 'surroundocc'),
     'labels_vs_lidar', '0.8 x the voxel size'),
    (broken_worlds.transposed_extrinsics, 'calibration',
     'lidar2cam is 179.4 deg'),
    (broken_worlds.swapped_cameras, 'calibration',
     'the two images disagree'),
    (broken_worlds.resized_images, 'calibration',
     'the image is 80x45 but its calibration is for 160x90'),
    (broken_worlds.missing_sweep, 'sequence', 'file missing'),
    (broken_worlds.sweeps_without_ego_motion, 'sequence',
     'sweeps would be merged with the wrong poses'),
], ids=['labels in the ego frame', 'shifted origin', 'flipped axis',
        'wrong voxel size', 'transposed extrinsic', 'swapped cameras',
        'images resized after calibration', 'missing sweep',
        'sweeps without ego motion'])
def test_broken_world_fails_naming_the_check(world_copy, damage, check,
                                             named):
    """SurroundOcc config; the label bugs move the labels against the
    points (as configured 0.11-0.85 of the points on labelled surfaces,
    0.96-0.98 read the way the bug wrote them); sweeps merged as if the
    car stood still are 2.4-2.5 m off (the car drives at 4.9 m/s)."""
    damage(world_copy)
    report = _doctor(world_copy)
    assert report.verdict == FAIL
    assert _failing(report) == {check}
    assert named in _sentences(report, check)
    if check == 'labels_vs_lidar':
        numbers = report.summaries[check].numbers
        assert numbers['best_other.gain']['min'] > 0.1
        assert numbers['best_other.hit']['max'] > 0.9 or numbers[
            'best_other.hit_elevated']['max'] > 0.9
    if 'merged' in named:
        numbers = report.summaries[check].numbers
        assert numbers['sweep_pose_error_m']['min'] > 2.0


def test_occ3d_labels_in_the_lidar_frame(world_copy):
    """Occ3D's ego-frame labels written in the LiDAR frame: 0.04-0.07 of
    the points lie on them as configured, 0.95 read in the LiDAR frame."""
    broken_worlds.labels_in_other_frame(world_copy, 'occ3d')
    report = _doctor(world_copy, 'occ3d')
    assert 'labels_vs_lidar' in _failing(report)
    assert 'in the LiDAR frame' in _sentences(report, 'labels_vs_lidar')
    assert report.summaries['labels_vs_lidar'].numbers['hit']['max'] < 0.4
