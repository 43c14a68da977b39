"""Robustness scores of a model under corruption, from its metrics.

Two benchmarks' summaries, on any metric in percent (mIoU, IoU, RayIoU):

* MultiCorrupt (Beemelmanns et al., IV 2024), resistance ability:
  ``RA_c,s = M_c,s / M_clean``, ``RA_c`` the mean over the severities of
  condition c, ``mRA`` the mean of ``RA_c`` over the conditions.
* RoboBEV (Xie et al., 2023), resilience rate: ``RR_c = sum_s M_c,s /
  (S * M_clean)``, the same number as ``RA_c`` (in percent there), and
  ``mRR`` its mean; and, against a baseline model B, the corruption
  error ``CE_c = sum_s (100 - M_c,s) / sum_s (100 - M^B_c,s)`` (in percent)
  with ``mCE`` its mean (below 100: fewer errors than the baseline).

Both benchmarks average three severities; here the ones evaluated
(``robustness.json`` records which). ``conditions`` is ``{condition:
{severity: metrics dict}}`` throughout, ``clean`` a metrics dict.
"""
import math
from typing import Dict, Mapping

Metrics = Mapping[str, float]
Runs = Mapping[str, Mapping[int, Metrics]]


def _value(metrics: Metrics, metric: str) -> float:
    value = metrics.get(metric)
    return float('nan') if value is None else float(value)


def _mean(values) -> float:
    values = [v for v in values if not math.isnan(v)]
    return sum(values) / len(values) if values else float('nan')


def resistance_ability(clean: Metrics, conditions: Runs,
                       metric: str) -> Dict[str, object]:
    """MultiCorrupt's RA per condition and severity, RA_c and mRA.

    Args:
        clean (Mapping[str, float]): The clean run's metrics.
        conditions (Mapping): ``{condition: {severity: metrics}}``.
        metric (str): Key of the metric, e.g. ``'occ/mIoU'``.

    Returns:
        dict: ``per_severity`` ``{condition: {severity: RA}}``, ``RA``
        ``{condition: RA_c}`` and ``mRA`` (ratios; NaN where the clean
        metric is 0 or missing).
    """
    reference = _value(clean, metric)
    usable = not math.isnan(reference) and reference != 0
    per_severity = {
        name: {
            severity: (_value(metrics, metric) / reference
                       if usable else float('nan'))
            for severity, metrics in runs.items()
        }
        for name, runs in conditions.items()
    }
    ra = {name: _mean(ratios.values())
          for name, ratios in per_severity.items()}
    return dict(per_severity=per_severity, RA=ra, mRA=_mean(ra.values()))


def resilience_rate(clean: Metrics, conditions: Runs,
                    metric: str) -> Dict[str, object]:
    """RoboBEV's RR_c and mRR, in percent (``100 * RA_c``).

    Returns:
        dict: ``RR`` ``{condition: RR_c}`` and ``mRR``.
    """
    ra = resistance_ability(clean, conditions, metric)
    return dict(RR={name: 100.0 * value for name, value in ra['RA'].items()},
                mRR=100.0 * ra['mRA'])


def corruption_error(conditions: Runs, baseline: Runs,
                     metric: str) -> Dict[str, object]:
    """RoboBEV's CE_c against a baseline model and mCE, in percent.

    Only the conditions and severities both runs hold are compared.

    Args:
        conditions (Mapping): The model's ``{condition: {severity:
            metrics}}``.
        baseline (Mapping): The baseline model's, alike.
        metric (str): A metric in percent.

    Returns:
        dict: ``CE`` ``{condition: CE_c}`` and ``mCE``; NaN for a
        condition the baseline scores at 100.
    """
    ce = {}
    for name, runs in conditions.items():
        shared = sorted(set(runs) & set(baseline.get(name, {})))
        if not shared:
            continue
        errors = sum(100.0 - _value(runs[s], metric) for s in shared)
        reference = sum(100.0 - _value(baseline[name][s], metric)
                        for s in shared)
        ce[name] = (100.0 * errors / reference
                    if reference > 0 else float('nan'))
    return dict(CE=ce, mCE=_mean(ce.values()))
