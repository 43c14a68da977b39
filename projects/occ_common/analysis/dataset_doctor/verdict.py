"""Verdicts of the dataset doctor: one per check and sample, with numbers.

A check returns a :class:`CheckResult`: its family (``'calibration'``,
``'labels_vs_lidar'``, ...), the numbers it measured and what it found
wrong, each finding a warning or a failure. The verdict is the worst of
its findings: ``fail`` (training on this data would be wasted: a frame
mix-up, a calibration that does not project the LiDAR onto the image
edges, a missing file), ``warn`` (unusual, worth a look, may be
intended), ``pass``, or ``skip`` when the sample has nothing to check
(no labels, no images). :func:`summarise` folds the per-sample results of
one check into the split's verdict and the numbers' mean, minimum and
maximum.
"""
from dataclasses import dataclass, field
from typing import Dict, Iterable, List, Optional, Sequence

import numpy as np

PASS, WARN, FAIL, SKIP = 'pass', 'warn', 'fail', 'skip'
#: Verdicts from the best to the worst; a missing check ranks lowest.
VERDICTS = (SKIP, PASS, WARN, FAIL)
#: The sample name of a check's result over the whole split.
SPLIT = '(split)'
_RANK = {verdict: rank for rank, verdict in enumerate(VERDICTS)}


def worst(verdicts: Iterable[str]) -> str:
    """The worst of ``verdicts`` (``skip`` for none).

    Args:
        verdicts (Iterable[str]): Members of :data:`VERDICTS`.

    Returns:
        str: ``fail`` over ``warn`` over ``pass`` over ``skip``.
    """
    return max(verdicts, key=_RANK.__getitem__, default=SKIP)


@dataclass
class CheckResult:
    """What one check found on one sample (or on the whole split).

    Args:
        check (str): The check's family, e.g. ``'calibration'``.
        numbers (dict[str, float]): What it measured, flat keys such as
            ``'CAM_FRONT.edge_alignment'``.
        findings (list[tuple[str, str]]): ``(verdict, sentence)`` per
            problem, the sentence naming the camera / file / number.
        skipped (str): Why there was nothing to check ('' if checked).
    """
    check: str
    numbers: Dict[str, float] = field(default_factory=dict)
    findings: List[tuple] = field(default_factory=list)
    skipped: str = ''

    @property
    def verdict(self) -> str:
        """str: ``skip``, or the worst finding (``pass`` for none)."""
        if self.skipped:
            return SKIP
        return worst([PASS] + [verdict for verdict, _ in self.findings])

    def fail(self, sentence: str) -> None:
        """Record a failure."""
        self.findings.append((FAIL, sentence))

    def warn(self, sentence: str) -> None:
        """Record a warning."""
        self.findings.append((WARN, sentence))

    def judge(self, value: float, sentence: str, fail_if, warn_if=None
              ) -> None:
        """Record ``sentence`` as a failure if ``fail_if(value)``, else as a
        warning if ``warn_if(value)``.

        Args:
            value (float): The measured number.
            sentence (str): Says what is wrong; formatted with ``value``.
            fail_if (Callable[[float], bool]): Failure predicate.
            warn_if (Callable[[float], bool], optional): Warning predicate.
        """
        if fail_if(value):
            self.fail(sentence.format(value=value))
        elif warn_if is not None and warn_if(value):
            self.warn(sentence.format(value=value))


@dataclass
class CheckSummary:
    """One check over the checked samples of a split.

    Args:
        check (str): The check's family.
        verdict (str): The worst verdict of its samples and of its
            split-level result, if any.
        counts (dict[str, int]): Checked samples per verdict (the
            split-level result is not a sample: it is ``split_verdict``).
        numbers (dict[str, dict[str, float]]): Per number: ``mean``,
            ``min``, ``max`` over the results that measured it (a
            split-level number has one value).
        findings (list[tuple[str, str, str]]): ``(verdict, sample,
            sentence)``, failures first; the split-level result's sample
            is :data:`SPLIT`.
        split_verdict (str, optional): The verdict of the check's
            split-level result; None where it has none.
    """
    check: str
    verdict: str
    counts: Dict[str, int]
    numbers: Dict[str, Dict[str, float]]
    findings: List[tuple]
    split_verdict: Optional[str] = None


def summarise(check: str,
              results: Sequence[CheckResult],
              samples: Sequence[str],
              split_result: Optional[CheckResult] = None) -> CheckSummary:
    """Fold the per-sample results of one check.

    Args:
        check (str): The check's family.
        results (Sequence[CheckResult]): One per checked sample.
        samples (Sequence[str]): The sample (token) of each result.
        split_result (CheckResult, optional): The check's result over the
            whole split (the class histogram's, the label grid's): it
            counts in the verdict, numbers and findings, not as a sample.
            Defaults to None.

    Returns:
        CheckSummary: The summary; its numbers are finite values only.
    """
    counts = {verdict: 0 for verdict in VERDICTS}
    for result in results:
        counts[result.verdict] += 1
    results, samples = list(results), list(samples)
    if split_result is not None:
        results.append(split_result)
        samples.append(SPLIT)
    values: Dict[str, list] = {}
    findings = []
    for result, sample in zip(results, samples):
        for key, value in result.numbers.items():
            if value is not None and np.isfinite(value):
                values.setdefault(key, []).append(float(value))
        findings += [(verdict, sample, sentence)
                     for verdict, sentence in result.findings]
    findings.sort(key=lambda f: -_RANK[f[0]])
    numbers = {
        key: dict(mean=float(np.mean(v)), min=float(np.min(v)),
                  max=float(np.max(v)))
        for key, v in values.items()
    }
    return CheckSummary(
        check, worst(r.verdict for r in results), counts, numbers, findings,
        None if split_result is None else split_result.verdict)
