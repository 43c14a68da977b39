"""Tables, plots and summaries of a robustness run.

``tools/analysis_tools/robustness.py`` stores its runs as ``{'clean':
run, '<condition>/<severity>': run, ...}``, each run a dict with
``metrics`` (the evaluators' keys, in percent), ``samples``, ``seconds``
and ``cpu_seconds``. This module turns them into the summaries of
:mod:`projects.occ_common.evaluation.robustness_summary`, a markdown
report and one plot per metric against severity.
"""
import json
import math
import os.path as osp
from typing import Dict, List, Optional

from ..evaluation.robustness_summary import (corruption_error, resilience_rate,
                                             resistance_ability)
from ..transforms.corruptions import CONDITIONS

#: Metrics the robustness scores (RA, RR, CE) are computed for: higher is
#: better, in percent.
SCORED = ('occ/mIoU', 'occ/IoU', 'occ/RayIoU')


def by_condition(runs: Dict[str, dict]) -> Dict[str, Dict[int, dict]]:
    """``{condition: {severity: metrics}}`` of the corrupted runs, in the
    order of ``OccCorruption.CONDITIONS``."""
    out: Dict[str, Dict[int, dict]] = {}
    for key, run in runs.items():
        if key == 'clean':
            continue
        condition, severity = key.rsplit('/', 1)
        out.setdefault(condition, {})[int(severity)] = run['metrics']
    order = {name: i for i, name in enumerate(CONDITIONS)}
    return {name: dict(sorted(out[name].items()))
            for name in sorted(out, key=lambda n: order.get(n, len(order)))}


def reported_metrics(clean: dict) -> List[str]:
    """The metrics of the tables and plots: the scored ones, the
    subsets' and distance ranges' mIoU, and the calibration errors."""
    keys = [k for k in SCORED if k in clean]
    splits = [k for k in clean if k.startswith('occ/') and
              k.endswith('/mIoU') and k.count('/') == 2]
    # The weather / light subsets, then the distance ranges, nearest first.
    keys += [k for k in splits if not k.startswith('occ/dist_')]
    keys += [k for k in splits if k.startswith('occ/dist_')]
    keys += [k for k in ('calib/ECE', 'calib/nonempty/ECE') if k in clean]
    return keys


def load_baseline(path: Optional[str]) -> Optional[Dict[str, Dict]]:
    """A reference model's ``{condition: {severity: metrics}}`` from its
    robustness.json, or None without a path."""
    if path is None:
        return None
    if not osp.isfile(path):
        raise FileNotFoundError(f'--baseline-json: no such file {path}')
    with open(path) as f:
        runs = json.load(f).get('runs')
    if not runs:
        raise ValueError(f'{path} holds no runs of '
                         'tools/analysis_tools/robustness.py')
    return by_condition(runs)


def summarize(runs: Dict[str, dict],
              baseline: Optional[Dict[str, Dict]] = None) -> dict:
    """RA / mRA, RR / mRR and (with a baseline) CE / mCE per scored
    metric."""
    clean = runs['clean']['metrics']
    conditions = by_condition(runs)
    summary = {}
    for metric in (m for m in SCORED if m in clean):
        entry = resistance_ability(clean, conditions, metric)
        entry.update(resilience_rate(clean, conditions, metric))
        if baseline is not None:
            entry.update(corruption_error(conditions, baseline, metric))
        summary[metric] = entry
    return summary


def _cell(value: Optional[float], digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return '-'
    return f'{value:.{digits}f}'


def _score_table(metric: str, clean: dict, conditions: dict,
                 entry: dict) -> List[str]:
    severities = sorted({s for runs in conditions.values() for s in runs})
    head = ['condition', 'family'] + [f's{s}' for s in severities] + [
        'RA_c', 'RR_c (%)'
    ] + (['CE_c (%)'] if 'CE' in entry else [])
    lines = [
        f'### {metric} (clean {_cell(clean.get(metric))})', '',
        '| ' + ' | '.join(head) + ' |', '|' + ' --- |' * len(head)
    ]
    for name, runs in conditions.items():
        row = [name, CONDITIONS[name].family if name in CONDITIONS else '?']
        row += [_cell(runs[s].get(metric)) if s in runs else '-'
                for s in severities]
        row += [_cell(entry['RA'].get(name), 3),
                _cell(entry['RR'].get(name), 1)]
        if 'CE' in entry:
            row.append(_cell(entry['CE'].get(name), 1))
        lines.append('| ' + ' | '.join(row) + ' |')
    tail = f'mRA {_cell(entry["mRA"], 3)}, mRR {_cell(entry["mRR"], 1)} %'
    if 'mCE' in entry:
        tail += f', mCE {_cell(entry["mCE"], 1)} %'
    return lines + ['', tail, '']


def markdown(results: dict, summary: dict) -> str:
    """The report: settings, one table per scored metric (per severity,
    RA_c, RR_c, CE_c), every reported metric of every run, and the time
    of each run."""
    runs = results['runs']
    clean = runs['clean']['metrics']
    conditions = by_condition(runs)
    settings = results['settings']
    lines = [
        '# Robustness', '',
        f'`{settings["config"]}` with `{settings["checkpoint"]}`: '
        f'{runs["clean"]["samples"]} test samples (every '
        f'{settings["subset"]}), corruption seed {settings["seed"]}. '
        'Metrics in %; RA is MultiCorrupt\'s resistance ability, RR '
        'RoboBEV\'s resilience rate (the same ratio, in %), CE its '
        'corruption error against the baseline; all averaged over the '
        'severities run.', ''
    ]
    for metric, entry in summary.items():
        lines += _score_table(metric, clean, conditions, entry)
    metrics = reported_metrics(clean)
    head = ['run'] + metrics + ['s / sample', 'CPU-s / sample']
    lines += ['### Every metric', '', '| ' + ' | '.join(head) + ' |',
              '|' + ' --- |' * len(head)]
    for key, run in runs.items():
        per = max(run['samples'], 1)
        lines.append('| ' + ' | '.join(
            [key] + [_cell(run['metrics'].get(m)) for m in metrics] +
            [_cell(run['seconds'] / per), _cell(run['cpu_seconds'] / per)]) +
            ' |')
    return '\n'.join(lines) + '\n'


#: Line style of each family in the plots.
_STYLES = {'camera': '-', 'lidar': '--', 'cross-sensor': ':'}


def plot_metric(results: dict, metric: str, path: str) -> None:
    """``metric`` against severity (0 = clean), one line per condition."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    runs = results['runs']
    clean = runs['clean']['metrics'].get(metric, math.nan)
    conditions = by_condition(runs)
    fig, ax = plt.subplots(figsize=(9, 5), dpi=100)
    colours = plt.get_cmap('tab20')
    for i, (name, by_severity) in enumerate(conditions.items()):
        severities = [0] + list(by_severity)
        values = [clean] + [m.get(metric, math.nan)
                            for m in by_severity.values()]
        family = CONDITIONS[name].family if name in CONDITIONS else None
        ax.plot(severities, values, _STYLES.get(family, '-'), marker='o',
                markersize=3, color=colours(i % 20), label=name)
    ax.set_xlabel('severity (0: clean)')
    ax.set_ylabel(f'{metric} (%)')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc='center left', bbox_to_anchor=(1.0, 0.5))
    ax.set_title(f'{osp.basename(results["settings"]["config"])}: '
                 f'{metric}; solid camera, dashed LiDAR, dotted both',
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_name(metric: str) -> str:
    """File name of a metric's plot, e.g. ``occ_mIoU.png``."""
    return metric.replace('/', '_') + '.png'


def write_report(results: dict, out: str,
                 baseline: Optional[Dict[str, Dict]] = None) -> dict:
    """Write ``robustness.md`` and the plots into ``out``.

    Returns:
        dict: The summary (see :func:`summarize`).
    """
    summary = summarize(results['runs'], baseline)
    with open(osp.join(out, 'robustness.md'), 'w') as f:
        f.write(markdown(results, summary))
    for metric in reported_metrics(results['runs']['clean']['metrics']):
        plot_metric(results, metric, osp.join(out, plot_name(metric)))
    return summary
