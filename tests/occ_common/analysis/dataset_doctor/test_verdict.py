"""Verdicts: the worst finding wins, and summaries fold the samples."""
import math

from projects.occ_common.analysis.dataset_doctor.verdict import (FAIL, PASS,
                                                                 SKIP, SPLIT,
                                                                 WARN,
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


def test_split_result_is_a_verdict_not_a_sample():
    """Two checked samples pass and the split-level histogram fails: the
    counts say 2 samples passed (the old fold said 3 samples, one of them
    the split, failed 1), the verdict is the split's failure, and its
    finding names the split."""
    samples = [CheckResult('class_histogram', numbers=dict(empty_share=0.9)),
               CheckResult('class_histogram', numbers=dict(empty_share=0.7))]
    split = CheckResult('class_histogram', numbers=dict(distance=0.4))
    split.fail('far from the reference')
    summary = summarise('class_histogram', samples, ['a', 'b'], split)
    assert summary.counts == {SKIP: 0, PASS: 2, WARN: 0, FAIL: 0}
    assert (summary.verdict, summary.split_verdict) == (FAIL, FAIL)
    assert summary.findings == [(FAIL, SPLIT, 'far from the reference')]
    assert summary.numbers['distance'] == dict(mean=0.4, min=0.4, max=0.4)
    assert summary.numbers['empty_share']['mean'] == 0.8
    assert summarise('masks', samples, ['a', 'b']).split_verdict is None
