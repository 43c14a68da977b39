"""Count ``torch.compile``'s graph breaks (and recompilations) of a
config's prediction or training step, and say where each break comes from.

Builds the config's model, preprocesses the benchmark's synthetic batch
(:mod:`projects.occ_common.synthetic.synthetic_batch`) and traces the
phase with ``torch._dynamo.explain`` (an eager backend: nothing is
compiled, so it runs on the CPU in seconds); see
:mod:`projects.occ_common.analysis.compile_check`::

    python tools/analysis_tools/graph_breaks.py CONFIG \\
        [--phase predict train] [--num-points N] [--recompile] \\
        [--cpu-path] [--json OUT] [--cfg-options ...]

``--recompile`` also compiles the phase (a backend that only counts
graphs) and calls it on a second batch of another point count, its points
marked dynamic as ``TorchCompileHook`` marks them: every graph of that
second call is a recompilation, printed with the guard that failed.
Under Dynamo the models take their GPU code path on every device;
``--cpu-path`` forces the CPU's (data-dependent shapes: what a CPU run
broke on before the compiled path followed the GPU's).
"""
import argparse
import contextlib
import json
from typing import Dict, List

import torch
from mmengine.config import DictAction

from projects.occ_common.analysis.compile_check import (PHASES,
                                                        count_recompiles,
                                                        explain_breaks,
                                                        phase_call)
from projects.occ_common.apis import init_model
from projects.occ_common.engine.config_checks import cfg_errors_exit
from projects.occ_common.engine.hooks.torch_compile_hook import \
    mark_dynamic_points
from projects.occ_common.synthetic.synthetic_batch import synthetic_batch
from projects.occ_common.utils.device_path import forced_accelerator_path

#: Points per cloud of the default batches: enough for every tiny config's
#: lift and voxelisation, few enough that a trace takes seconds.
DEFAULT_POINTS = 4000


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(
        description='Count torch.compile graph breaks of a config.')
    parser.add_argument('config', help='config file')
    parser.add_argument('--phase', nargs='+', choices=PHASES,
                        default=['predict'],
                        help='predict (default), train (the loss forward)')
    parser.add_argument('--num-points', type=int, default=DEFAULT_POINTS,
                        help=f'points per synthetic cloud (default '
                        f'{DEFAULT_POINTS})')
    parser.add_argument('--batch', type=int, default=1,
                        help='samples per batch (default 1)')
    parser.add_argument('--recompile', action='store_true',
                        help='also count recompilations between two '
                        'batches of different point counts')
    parser.add_argument('--cpu-path', action='store_true',
                        help="trace the CPU's code path (default: the path "
                        'compiled code takes, the GPU\'s)')
    parser.add_argument('--json', help='also write the counts here')
    parser.add_argument('--cfg-options', nargs='+', action=DictAction,
                        help='overrides, key=value')
    args = parser.parse_args(argv)
    if args.num_points < 2 or args.batch < 1:
        parser.error('--num-points must be >= 2 and --batch >= 1')
    return args


def preprocessed(model, cfg, batch_size: int, num_points: int, train: bool,
                 seed: int = 0) -> dict:
    """The data preprocessor's output of a synthetic batch, its points
    marked dynamic."""
    batch, _ = synthetic_batch(cfg, batch_size, num_points, labels=train,
                               seed=seed)
    data = model.data_preprocessor(batch, train)
    mark_dynamic_points(data)
    return data


def check_phase(model, cfg, phase: str, args) -> Dict:
    """Breaks (and recompilations) of one phase."""
    train = phase == 'train'
    call = phase_call(model, phase)
    # Fresh batches for every call: a prediction writes into its samples.
    report = explain_breaks(
        call, preprocessed(model, cfg, args.batch, args.num_points, train))
    result = dict(phase=phase, graphs=report.graphs,
                  breaks=len(report.breaks), ops=report.ops,
                  sites=report.by_site())
    if args.recompile:
        recompiles = count_recompiles(call, [
            preprocessed(model, cfg, args.batch, args.num_points, train),
            preprocessed(model, cfg, args.batch, args.num_points * 3 // 4,
                         train, seed=1)
        ])
        result.update(graphs_per_call=recompiles.graphs_per_call,
                      recompiles=recompiles.recompiles,
                      recompile_reasons=recompiles.reasons)
    return result


def format_result(result: Dict) -> str:
    """One phase's summary and its break sites."""
    lines = [f'{result["phase"]}: {result["breaks"]} graph breaks, '
             f'{result["graphs"]} graphs, {result["ops"]} operators']
    for site in result['sites']:
        lines.append(f'  {site["count"]:3d} x {site["location"]} '
                     f'({site["function"]}): {site["reason"]}')
        if site['code']:
            lines.append(f'        {site["code"]}')
    if 'recompiles' in result:
        lines.append(f'  recompilations on a second point count: '
                     f'{result["recompiles"]} (graphs per call '
                     f'{result["graphs_per_call"]})')
        lines.extend(f'    {line}' for reason in result['recompile_reasons']
                     for line in reason.splitlines())
    return '\n'.join(lines)


def main(argv=None) -> Dict:
    args = parse_args(argv)
    torch.manual_seed(0)
    with cfg_errors_exit():
        model = init_model(args.config, cfg_options=args.cfg_options)
    cfg = model.cfg
    report = dict(config=args.config, num_points=args.num_points,
                  batch=args.batch, path='cpu' if args.cpu_path else
                  'compiled (GPU)', phases=[])
    results: List[Dict] = report['phases']
    with forced_accelerator_path(False) if args.cpu_path else \
            contextlib.nullcontext():
        for phase in args.phase:
            results.append(check_phase(model, cfg, phase, args))
            print(format_result(results[-1]))
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(report, f, indent=1)
    return report


if __name__ == '__main__':
    main()
