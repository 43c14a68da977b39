"""The doctor's report: ``report.md`` for a person, ``report.json`` for a
script.

The markdown opens with the verdict and one row per check family (its
verdict, how many samples passed, warned, failed or were skipped, the
verdict over the whole split where the family has one, and its headline
numbers), then lists the findings (the failures first, each
naming its sample), the pictures, and per family every number's mean,
minimum and maximum over the checked samples. The JSON holds the same and
every sample's own numbers.
"""
import json
import math
import os
import os.path as osp
from collections import Counter
from typing import Dict, List

from .doctor import CHECKS, DoctorReport
from .verdict import VERDICTS, CheckSummary

#: Findings listed per family (the JSON has all of them).
MAX_FINDINGS = 20


def headline(summary: CheckSummary) -> str:
    """The few numbers that say most about a family, as text."""
    numbers = summary.numbers

    def over(suffix: str, stat: str, pick) -> float:
        values = [v[stat] for k, v in numbers.items() if k.endswith(suffix)]
        return pick(values) if values else math.nan

    if summary.check == 'calibration':
        parts = [('min overlap consistency',
                  over('.overlap_consistency', 'min', min)),
                 ('mean edge alignment',
                  _mean([v['mean'] for k, v in numbers.items()
                         if k.endswith('.edge_alignment')])),
                 ('max extrinsic deg', over('.extrinsic_deg', 'max', max))]
    elif summary.check == 'labels_vs_lidar':
        parts = [('hit', numbers.get('hit', {}).get('mean', math.nan)),
                 ('best other reading\'s gain',
                  numbers.get('best_other.gain', {}).get('max', math.nan)),
                 ('same class',
                  numbers.get('same_class', {}).get('mean', math.nan))]
    elif summary.check == 'label_grid':
        parts = [('range diff m', over('range_diff_m', 'max', max)),
                 ('voxel diff m', over('voxel_diff_m', 'max', max))]
    elif summary.check == 'masks':
        parts = [(key.replace('_', ' '),
                  numbers.get(key, {}).get('mean', math.nan))
                 for key in ('camera_coverage', 'points_in_lidar_mask',
                             'camera_mask_in_view')]
    elif summary.check == 'sequence':
        parts = [('sweeps', over('sweeps', 'mean', max)),
                 ('max speed m/s', over('speed_mps', 'max', max)),
                 ('max sweep gap s', over('max_sweep_gap_s', 'max', max))]
    else:
        parts = [('distance to reference',
                  numbers.get('distance', {}).get('mean', math.nan)),
                 ('empty share',
                  numbers.get('empty_share', {}).get('mean', math.nan))]
    return ', '.join(f'{name} {value:.3g}' for name, value in parts
                     if not math.isnan(value)) or '-'


def _mean(values: List[float]) -> float:
    return sum(values) / len(values) if values else math.nan


def _markdown(report: DoctorReport) -> str:
    lines = [
        f'# Dataset check: {osp.basename(report.config)}', '',
        f'Split `{report.split}` of `{report.ann_file}` (data root '
        f'`{report.data_root}`): {len(report.tokens)} of '
        f'{report.num_samples} samples checked, '
        f'{report.seconds_per_sample:.2f} s per sample.', '',
        f'**Verdict: {report.verdict.upper()}**', '',
        '| check | verdict | samples ' + ' / '.join(VERDICTS) +
        ' | headline numbers (mean over samples) |',
        '| --- | --- | --- | --- |'
    ]
    for check in CHECKS:
        summary = report.summaries[check]
        counts = ' / '.join(str(summary.counts[v]) for v in VERDICTS)
        if summary.split_verdict is not None:
            counts += f'; split: {summary.split_verdict}'
        lines.append(f'| {check} | **{summary.verdict}** | {counts} | '
                     f'{headline(summary)} |')
    lines += ['', '## Findings', '']
    found = False
    for check in CHECKS:
        findings = report.summaries[check].findings
        if not findings:
            continue
        found = True
        repeats = Counter(sentence for _, _, sentence in findings)
        lines.append(f'### {check}')
        shown = set()
        for verdict, sample, sentence in findings:
            if sentence in shown:
                continue
            shown.add(sentence)
            more = repeats[sentence] - 1
            lines.append(f'- **{verdict}** ({sample}'
                         + (f' and {more} more' if more else '')
                         + f'): {sentence}')
            if len(shown) >= MAX_FINDINGS:
                lines.append(f'- ... {len(findings) - MAX_FINDINGS} more in'
                             ' report.json')
                break
        lines.append('')
    if not found:
        lines += ['None.', '']
    if report.pictures:
        lines += ['## Pictures', '']
        lines += [f'![{osp.basename(p)}]({p})' for p in report.pictures]
        lines.append('')
    lines += ['## Numbers', '']
    for check in CHECKS:
        numbers = report.summaries[check].numbers
        if not numbers:
            continue
        lines += [f'<details><summary>{check}: {len(numbers)} numbers'
                  '</summary>', '', '| number | mean | min | max |',
                  '| --- | ---: | ---: | ---: |']
        lines += [f'| {key} | {v["mean"]:.4g} | {v["min"]:.4g} | '
                  f'{v["max"]:.4g} |' for key, v in sorted(numbers.items())]
        lines += ['', '</details>', '']
    return '\n'.join(lines)


def _as_json(report: DoctorReport) -> Dict:
    def clean(numbers):
        return {k: (None if isinstance(v, float) and not math.isfinite(v)
                    else v) for k, v in numbers.items()}

    return dict(
        config=report.config, split=report.split, ann_file=report.ann_file,
        data_root=report.data_root, num_samples=report.num_samples,
        seconds_per_sample=clean(
            dict(s=report.seconds_per_sample))['s'],
        verdict=report.verdict, pictures=report.pictures,
        checks={
            check: dict(verdict=s.verdict, counts=s.counts,
                        split_verdict=s.split_verdict,
                        numbers=s.numbers,
                        findings=[dict(verdict=v, sample=t, text=x)
                                  for v, t, x in s.findings])
            for check, s in report.summaries.items()
        },
        samples=[
            dict(token=token, checks={
                check: dict(verdict=r.verdict, skipped=r.skipped,
                            numbers=clean(r.numbers))
                for check, r in results.items()
            }) for token, results in zip(report.tokens, report.results)
        ])


def write_report(report: DoctorReport, out_dir: str) -> Dict[str, str]:
    """Write ``report.md`` and ``report.json`` into ``out_dir``.

    Args:
        report (DoctorReport): From :func:`~.doctor.run_doctor`.
        out_dir (str): Folder (created if missing).

    Returns:
        dict[str, str]: ``markdown`` and ``json``: the files written.
    """
    os.makedirs(out_dir, exist_ok=True)
    paths = dict(markdown=osp.join(out_dir, 'report.md'),
                 json=osp.join(out_dir, 'report.json'))
    with open(paths['markdown'], 'w') as f:
        f.write(_markdown(report) + '\n')
    with open(paths['json'], 'w') as f:
        json.dump(_as_json(report), f, indent=1, allow_nan=False,
                  default=float)
    return paths
