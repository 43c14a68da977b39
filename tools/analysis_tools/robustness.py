#!/usr/bin/env python
"""How a trained model holds up when its sensors fail, weather hits or
calibration drifts.

    python tools/analysis_tools/robustness.py CONFIG CHECKPOINT \\
        --out work_dirs/robustness [--conditions fog camera_crash ...] \\
        [--severities 1 3 5] [--subset EVERY_N] [--ece] \\
        [--baseline-json OTHER/robustness.json] [--cfg-options ...]

Runs the config's test set clean and under every condition x severity of
``OccCorruption`` (docs/robustness.md), corrupted on the fly as each
sample is loaded, through the config's own evaluators (IoU, mIoU, the
rainy / night / distance splits, RayIoU where configured) and writes to
``--out``:

* ``robustness.json``: the settings, every run's metrics, wall and CPU
  seconds, and the summaries: MultiCorrupt's resistance ability (RA per
  condition and severity, RA_c, mRA), RoboBEV's resilience rate (RR_c,
  mRR) and, with ``--baseline-json`` (another model's robustness.json),
  its corruption error (CE_c, mCE);
* ``robustness.md``: the same as tables;
* ``<metric>.png``: each reported metric against severity, one line per
  condition.

``--ece`` adds the expected calibration error of the voxel class
probabilities (``OccupancyCalibrationMetric``): the predictions are then
the argmax of the model's tensor-mode logits, checked against its
``predict`` on the first sample. A run resumes: runs already in
``robustness.json`` with the same settings are kept, so conditions can be
added later. The time the whole run will take is estimated from one
sample before it starts.
"""
import argparse
import json
import logging
import os
import os.path as osp
import sys
import time

import torch

from projects.occ_common.engine.config_checks import (CfgOptionsAction,
                                                      cfg_errors_exit)

#: Severities evaluated by default: MultiCorrupt's three levels are this
#: library's 1, 3 and 5 for the conditions both define.
DEFAULT_SEVERITIES = (1, 3, 5)
RESULTS = 'robustness.json'


def parse_args(argv=None):
    """Parse the command line."""
    from projects.occ_common.transforms.corruptions import (CONDITIONS,
                                                            MAX_SEVERITY)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('config', help='model config')
    parser.add_argument('checkpoint', help='trained weights')
    parser.add_argument('--out', required=True, help='output folder')
    parser.add_argument(
        '--conditions', nargs='+', default=list(CONDITIONS),
        choices=list(CONDITIONS), metavar='NAME',
        help=f'conditions to run (default: all): {", ".join(CONDITIONS)}')
    parser.add_argument(
        '--severities', nargs='+', type=int,
        default=list(DEFAULT_SEVERITIES),
        choices=range(1, MAX_SEVERITY + 1), metavar='S',
        help=f'severities 1..{MAX_SEVERITY} (default: 1 3 5)')
    parser.add_argument('--subset', type=int, default=1, metavar='EVERY_N',
                        help='evaluate every n-th test sample (default: all)')
    parser.add_argument('--seed', type=int, default=0,
                        help='seed of the corruptions\' draws')
    parser.add_argument('--ece', action='store_true',
                        help='also the expected calibration error of the '
                        'voxel class probabilities')
    parser.add_argument('--baseline-json', default=None,
                        help='robustness.json of a reference model, for '
                        'the corruption error (CE, mCE)')
    parser.add_argument('--device', default='cpu')
    parser.add_argument(
        '--allow-key-mismatch', action='store_true',
        help="evaluate a checkpoint whose keys or shapes differ from the "
        "model's (missing ones keep their initialisation)")
    parser.add_argument('--cfg-options', nargs='+', action=CfgOptionsAction,
                        help='config overrides, as for tools/test.py')
    args = parser.parse_args(argv)
    if args.subset < 1:
        parser.error(f'--subset must be >= 1, got {args.subset}')
    args.severities = sorted(set(args.severities))
    args.conditions = list(dict.fromkeys(args.conditions))
    return args


def settings_of(args) -> dict:
    """What makes two runs comparable (a resumed run must match)."""
    return dict(config=args.config, checkpoint=args.checkpoint,
                cfg_options=getattr(args, 'cfg_options_raw', None) or {},
                subset=args.subset, seed=args.seed, ece=args.ece)


def build_evaluator(cfg, empty_index=None):
    """The config's test evaluators; with ``empty_index`` (the model's
    empty label) also the calibration metric, counting the voxels the
    config's ``OccupancyMetric`` counts."""
    from mmengine.evaluator import Evaluator
    metrics = cfg.test_evaluator
    metrics = [dict(m) for m in (metrics if isinstance(
        metrics, (list, tuple)) else [metrics])]
    if empty_index is not None:
        occ = [m for m in metrics if m.get('type') == 'OccupancyMetric']
        masked = bool(occ) and occ[0].get('convention') == 'occ3d' and \
            occ[0].get('use_camera_mask', True)
        metrics.append(dict(type='OccupancyCalibrationMetric',
                            empty_index=int(empty_index),
                            use_camera_mask=masked))
    return Evaluator(metrics)


def voxel_logits(output) -> torch.Tensor:
    """The finest-scale class logits of a tensor-mode forward (a list per
    scale for OccCylindrical). Shape (B, K, X, Y, Z)."""
    return output[0] if isinstance(output, (list, tuple)) else output


def predict(model, sample: dict, with_logits: bool):
    """Predicted data samples of one sample (and their logits)."""
    from mmengine.dataset import pseudo_collate
    batch = pseudo_collate([sample])
    with torch.no_grad():
        data = model.data_preprocessor(batch, False)
        if not with_logits:
            return batch, model(**data, mode='predict')
        logits = voxel_logits(model(**data, mode='tensor'))
        samples = data['data_samples']
        for item, grid in zip(samples, logits):
            item.pred_logits = grid
            item.pred_occ = grid.argmax(dim=0)
        return batch, samples


def check_logits_predict(model, sample: dict) -> None:
    """The argmax of the tensor-mode logits is what ``predict`` says."""
    _, by_logits = predict(model, sample, True)
    _, by_predict = predict(model, sample, False)
    for ours, theirs in zip(by_logits, by_predict):
        differ = int((ours.pred_occ != theirs.pred_occ).sum())
        if differ:
            raise SystemExit(
                f'--ece: {type(model).__name__}\'s predict differs from the '
                f'argmax of its tensor-mode logits in {differ} voxels; its '
                'calibration cannot be measured this way')


def evaluate(model, dataset, evaluator, with_logits: bool, bar) -> dict:
    """Metrics, seconds and CPU seconds of one pass over ``dataset``."""
    start, cpu = time.perf_counter(), time.process_time()
    for index in range(len(dataset)):
        batch, samples = predict(model, dataset[index], with_logits)
        evaluator.process(data_samples=samples, data_batch=batch)
        bar.update()
    metrics = evaluator.evaluate(len(dataset))
    return dict(
        metrics={k: float(v) for k, v in metrics.items()
                 if isinstance(v, (int, float))},
        samples=len(dataset),
        seconds=time.perf_counter() - start,
        cpu_seconds=time.process_time() - cpu)


def load_previous(path: str, settings: dict) -> dict:
    """Runs of an earlier invocation with the same settings (else none)."""
    if not osp.isfile(path):
        return {}
    with open(path) as f:
        old = json.load(f)
    if old.get('settings') != settings:
        raise SystemExit(
            f'{path} holds runs of other settings ({old.get("settings")} != '
            f'{settings}); use another --out')
    return old.get('runs', {})


def run_key(condition, severity) -> str:
    """``'clean'`` or ``'<condition>/<severity>'``."""
    return 'clean' if condition is None else f'{condition}/{severity}'


def main(argv=None) -> dict:
    """Run the clean set and every condition x severity; write the
    report. Returns the results."""
    from mmengine.logging import MMLogger
    from mmengine.utils import ProgressBar

    from projects.occ_common.analysis.robustness_report import (load_baseline,
                                                                write_report)
    from projects.occ_common.apis import build_corrupted_dataset, init_model
    from projects.occ_common.apis.split_dataset import load_tool_config

    args = parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    path = osp.join(args.out, RESULTS)
    settings = settings_of(args)
    runs = load_previous(path, settings)
    cfg = load_tool_config(args)
    model = init_model(cfg, args.checkpoint, args.device,
                       allow_key_mismatch=args.allow_key_mismatch)
    if args.ece and getattr(model, 'empty_index', None) is None:
        raise SystemExit(f'--ece: {type(model).__name__} has no empty_index '
                         '(an occupancy detector of this library has)')
    # The metrics print a table per run; the report has them.
    MMLogger.get_current_instance().setLevel(logging.WARNING)
    todo = [(None, 0)] + [(c, s) for c in args.conditions
                          for s in args.severities]
    todo = [(c, s) for c, s in todo if run_key(c, s) not in runs]
    baseline = load_baseline(args.baseline_json)

    clean = build_corrupted_dataset(cfg, every=args.subset)
    if args.ece:
        check_logits_predict(model, clean[0])
    if todo:
        start = time.perf_counter()
        predict(model, clean[0], args.ece)
        per_sample = time.perf_counter() - start
        total = len(todo) * len(clean)
        print(f'{len(todo)} runs x {len(clean)} samples: about '
              f'{per_sample * total / 60:.1f} min at the '
              f'{per_sample:.2f} s of one clean sample (corruptions add '
              'their own time)', flush=True)
        bar = ProgressBar(total, file=sys.stdout)
    for condition, severity in todo:
        dataset = clean if condition is None else build_corrupted_dataset(
            cfg, condition, severity, args.seed, args.subset)
        evaluator = build_evaluator(
            cfg, model.empty_index if args.ece else None)
        runs[run_key(condition, severity)] = evaluate(
            model, dataset, evaluator, args.ece, bar)
        results = dict(settings=settings, runs=runs)
        with open(path, 'w') as f:  # after every run: a kill loses one
            json.dump(results, f, indent=1)
    results = dict(settings=settings, runs=runs)
    report = write_report(results, args.out, baseline)
    results['summary'] = report
    with open(path, 'w') as f:
        json.dump(results, f, indent=1)
    print(f'\nwrote {path}, {osp.join(args.out, "robustness.md")} and the '
          'plots')
    return results


if __name__ == '__main__':
    with cfg_errors_exit():
        main()
