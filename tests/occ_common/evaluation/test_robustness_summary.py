"""MultiCorrupt's RA / mRA and RoboBEV's RR / mRR / CE / mCE on numbers
worked out by hand."""
import math

import pytest

from projects.occ_common.evaluation import (corruption_error, resilience_rate,
                                            resistance_ability)

M = 'occ/mIoU'
CLEAN = {M: 40.0}
#: The model: fog 36 / 30, no LiDAR 20 / 10 at severities 1 / 3.
MODEL = {'fog': {1: {M: 36.0}, 3: {M: 30.0}},
         'lidar_missing': {1: {M: 20.0}, 3: {M: 10.0}}}
#: The baseline: fog 30 / 20, no LiDAR 25 / 15, and a severity 5 of fog
#: the model was not run at (left out of the comparison).
BASELINE = {'fog': {1: {M: 30.0}, 3: {M: 20.0}, 5: {M: 5.0}},
            'lidar_missing': {1: {M: 25.0}, 3: {M: 15.0}}}


def test_resistance_ability():
    """RA_fog = (36/40 + 30/40) / 2 = (0.9 + 0.75) / 2 = 0.825,
    RA_lidar = (0.5 + 0.25) / 2 = 0.375, mRA = (0.825 + 0.375) / 2 = 0.6."""
    ra = resistance_ability(CLEAN, MODEL, M)
    assert ra['per_severity']['fog'] == {1: 0.9, 3: 0.75}
    assert ra['RA'] == pytest.approx({'fog': 0.825, 'lidar_missing': 0.375})
    assert ra['mRA'] == pytest.approx(0.6)


def test_resilience_rate_is_ra_in_percent():
    """RR_c = sum_s M_c,s / (S * M_clean): fog (36 + 30) / (2 * 40) =
    82.5 %, no LiDAR 30 / 80 = 37.5 %, mRR 60 %."""
    rr = resilience_rate(CLEAN, MODEL, M)
    assert rr['RR'] == pytest.approx({'fog': 82.5, 'lidar_missing': 37.5})
    assert rr['mRR'] == pytest.approx(60.0)


def test_corruption_error_against_a_baseline():
    """CE_fog = ((100-36) + (100-30)) / ((100-30) + (100-20)) = 134 / 150
    = 89.33 %; CE_lidar = (80 + 90) / (75 + 85) = 170 / 160 = 106.25 %;
    mCE = 97.79 %. The baseline's fog at 5 is not compared."""
    ce = corruption_error(MODEL, BASELINE, M)
    assert ce['CE'] == pytest.approx({'fog': 13400 / 150,
                                      'lidar_missing': 106.25})
    assert ce['mCE'] == pytest.approx((13400 / 150 + 106.25) / 2)


def test_missing_values_are_nan_not_zero():
    """A clean score of 0 leaves RA undefined; a condition the baseline
    never ran is left out of mCE."""
    ra = resistance_ability({M: 0.0}, MODEL, M)
    assert math.isnan(ra['mRA'])
    ce = corruption_error(MODEL, {'fog': BASELINE['fog']}, M)
    assert set(ce['CE']) == {'fog'}
    assert ce['mCE'] == pytest.approx(13400 / 150)
