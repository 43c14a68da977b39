#!/usr/bin/env python
"""Check a dataset before training on it: calibration, labels against the
LiDAR, visibility masks, sequence and class histogram.

    python tools/analysis_tools/check_dataset.py CONFIG --out DIR \\
        [--split val|train] [--samples N] [--pictures K] \\
        [--data-root DIR] [--cfg-options KEY=VALUE ...]

Reads the split's samples as the config's dataset lists them (files as
they are, no augmentation), gives every check a verdict (pass / warn /
fail, or skip when a sample has nothing to check) with its numbers, per
sample and over the split, and writes ``DIR/report.md`` (with pictures of
the first ``--pictures`` samples: the ground truth and the LiDAR points
projected into the cameras, and both from above) and ``DIR/report.json``.
Exits with status 1 when a check fails, so a training script can stop
before the GPU time is spent. What each check measures and why:
``docs/customize_dataset.md``.
"""
import argparse
import sys

from projects.occ_common.apis.split_dataset import (add_split_arguments,
                                                    load_tool_config)
from projects.occ_common.engine.config_checks import (CfgOptionsAction,
                                                      cfg_errors_exit)


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('config', help='a config of this library')
    add_split_arguments(parser)
    parser.add_argument('--out', required=True,
                        help='folder for report.md, report.json, pictures/')
    parser.add_argument('--samples', type=int, default=None,
                        help='check this many samples, spread over the '
                        'split (default: all)')
    parser.add_argument('--pictures', type=int, default=2,
                        help='samples drawn (default 2)')
    parser.add_argument('--cfg-options', nargs='+', action=CfgOptionsAction,
                        help='config overrides, as for tools/test.py')
    args = parser.parse_args(argv)
    if args.samples is not None and args.samples < 1:
        parser.error(f'--samples must be >= 1, got {args.samples}')
    if args.pictures < 0:
        parser.error(f'--pictures must be >= 0, got {args.pictures}')
    return args


def main(argv=None):
    """Check, write the report, print its table; returns the report."""
    from projects.occ_common.analysis.dataset_doctor import (CHECKS,
                                                             run_doctor,
                                                             write_report)
    from projects.occ_common.analysis.dataset_doctor.report import headline
    args = parse_args(argv)
    cfg = load_tool_config(args)
    report = run_doctor(cfg, args.split, args.samples, args.out,
                        args.pictures, args.data_root)
    paths = write_report(report, args.out)
    print(f'{args.config} ({args.split}): {len(report.tokens)} of '
          f'{report.num_samples} samples, '
          f'{report.seconds_per_sample:.2f} s per sample')
    for check in CHECKS:
        summary = report.summaries[check]
        print(f'  {check:16s} {summary.verdict:5s} {headline(summary)}')
        for verdict, sample, sentence in summary.findings[:3]:
            print(f'    {verdict}: {sentence} ({sample})')
    print(f'verdict: {report.verdict}; report: {paths["markdown"]}')
    return report


def exit_status(report) -> int:
    """1 when a check failed, else 0 (warnings pass)."""
    from projects.occ_common.analysis.dataset_doctor import FAIL
    return 1 if report.verdict == FAIL else 0


if __name__ == '__main__':
    with cfg_errors_exit():
        sys.exit(exit_status(main()))
