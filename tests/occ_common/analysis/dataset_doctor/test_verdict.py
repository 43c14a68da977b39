"""Verdicts: the worst finding wins, and summaries fold the samples."""
import math

from projects.occ_common.analysis.dataset_doctor.verdict import (FAIL, PASS,
                                                                 SKIP, WARN,
                                                                 CheckResult,
                                                                 summarise,
                                                                 worst)


def test_worst_orders_fail_warn_pass_skip():
    assert worst([PASS, WARN, SKIP]) == WARN
    assert worst([PASS, FAIL, WARN]) == FAIL
    assert worst([SKIP, PASS]) == PASS
    assert worst([]) == SKIP  # the empty case: nothing was checked


def test_result_verdict_is_its_worst_finding():
    """No finding: pass; a warning then a failure: fail; skipped: skip
    whatever it found."""
    result = CheckResult('calibration')
    assert result.verdict == PASS
    result.warn('odd')
    assert result.verdict == WARN
    result.fail('wrong')
    assert result.verdict == FAIL
    assert CheckResult('masks', skipped='no masks').verdict == SKIP


def test_judge_formats_the_value_and_picks_the_level():
    """0.2 < 0.3: a failure; 0.5 < 0.6 (not < 0.3): a warning; 0.9:
    nothing; NaN compares false: nothing."""
    result = CheckResult('labels_vs_lidar')
    for value in (0.2, 0.5, 0.9, math.nan):
        result.judge(value, 'hit {value:.2f}', lambda v: v < 0.3,
                     lambda v: v < 0.6)
    assert result.findings == [(FAIL, 'hit 0.20'), (WARN, 'hit 0.50')]


def test_summarise_counts_and_folds_numbers():
    """Two samples measure hit 0.8 and 1.0 (mean 0.9); one has a NaN
    that is left out; the failure is listed first with its sample."""
    first = CheckResult('labels_vs_lidar', numbers=dict(hit=0.8, x=math.nan))
    first.warn('low')
    second = CheckResult('labels_vs_lidar', numbers=dict(hit=1.0))
    second.fail('shifted')
    skipped = CheckResult('labels_vs_lidar', skipped='no labels')
    summary = summarise('labels_vs_lidar', [first, second, skipped],
                        ['a', 'b', 'c'])
    assert summary.verdict == FAIL
    assert summary.counts == {SKIP: 1, PASS: 0, WARN: 1, FAIL: 1}
    assert summary.numbers == dict(hit=dict(mean=0.9, min=0.8, max=1.0))
    assert summary.findings == [(FAIL, 'b', 'shifted'), (WARN, 'a', 'low')]
