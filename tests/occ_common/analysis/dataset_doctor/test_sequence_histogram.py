"""The sequence and class-histogram checks' arithmetic, and the choice of
the samples to check."""
import numpy as np
import pytest

from projects.occ_common.analysis.dataset_doctor.class_histogram import (
    class_shares, reference_shares, split_histogram)
from projects.occ_common.analysis.dataset_doctor.doctor import sample_indices
from projects.occ_common.analysis.dataset_doctor.grid import LabelGrid
from projects.occ_common.analysis.dataset_doctor.sequence import motion
from projects.occ_common.analysis.dataset_doctor.verdict import CheckResult
from projects.occ_common.datasets.nuscenes_classes import OCC_CLASS_NAMES
from projects.occ_common.datasets.occ_formats import SURROUNDOCC_CLASS_NAMES


def _pose(x: float, y: float, yaw_deg: float) -> np.ndarray:
    yaw = np.radians(yaw_deg)
    pose = np.eye(4)
    pose[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    pose[:2, 3] = x, y
    return pose


def test_motion_between_two_poses():
    """3 m east and 4 m north in 0.5 s: 5 m / 0.5 s = 10 m/s; a turn from
    170 to -170 deg is 20 deg (across the wrap), 40 deg/s."""
    speed, yaw_rate = motion(_pose(0, 0, 170), _pose(3, 4, -170), 0.5)
    assert speed == pytest.approx(10.0)
    assert yaw_rate == pytest.approx(40.0)


def test_sample_indices_spread_over_the_split():
    """3 of 10 samples: 0, 4.5 -> 4 (half to even), 9; all when asking for
    more; none of an empty split; 0 samples is refused."""
    assert sample_indices(10, 3) == [0, 4, 9]
    assert sample_indices(5, None) == list(range(5))
    assert sample_indices(5, 9) == list(range(5))
    assert sample_indices(0, 3) == []
    with pytest.raises(ValueError, match='>= 1'):
        sample_indices(10, 0)


def test_split_histogram_distance():
    """A split of only cars has the shares 1 on car and 0 elsewhere; its
    total variation distance to a reference is 1 - the reference's car
    share (half of (1 - c) + the other shares, which add up to 1 - c)."""
    grid = LabelGrid('surroundocc', 'lidar', np.zeros(6), np.ones(3),
                     (1, 1, 1), SURROUNDOCC_CLASS_NAMES, 0)
    only_cars = CheckResult('class_histogram',
                            numbers={'voxels.car': 10.0, 'voxels.empty': 90})
    result = split_histogram([only_cars], grid, synthetic=False)
    reference, _ = reference_shares('surroundocc', synthetic=False)
    car = OCC_CLASS_NAMES.index('car')
    assert result.numbers['share.car'] == 1.0
    assert result.numbers['distance'] == pytest.approx(1 - reference[car])
    assert result.verdict == 'warn'  # 0.97 > 0.35
    assert class_shares({}).sum() == 0  # the empty case
    no_labels = split_histogram([CheckResult('class_histogram',
                                             skipped='no labels')], grid,
                                synthetic=True)
    assert no_labels.verdict == 'skip'


def test_references_are_distributions_of_the_16_classes():
    """Each reference's shares add up to 1 over the 16 classes; Occ3D's
    driveable surface is 32 % of its occupied voxels (175,883,646 of
    548,465,538)."""
    for fmt in ('surroundocc', 'occ3d'):
        for synthetic in (False, True):
            shares, source = reference_shares(fmt, synthetic)
            assert shares.shape == (16, ) and shares.sum() == pytest.approx(
                1.0)
            assert source
    occ3d, _ = reference_shares('occ3d', False)
    drive = OCC_CLASS_NAMES.index('driveable_surface')
    assert occ3d[drive] == pytest.approx(175883646 / 548465538)
