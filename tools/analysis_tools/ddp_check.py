"""Train configs for a few iterations under DDP, without a dataset.

Each config's model is trained by ``--ranks`` processes in one process
group (nccl with a GPU a rank on CUDA, gloo on the CPU), wrapped in
mmengine's ``MMDistributedDataParallel`` as ``tools/train.py`` wraps it
(``find_unused_parameters`` from the config), on random batches of the
config's shapes, one per rank (:mod:`projects.occ_common.analysis.ddp_check`).
It says, per config, whether DDP trained it, which trainable parameters
got no gradient, the losses, the seconds a step and (CUDA) the peak
memory, and whether every rank ended with rank 0's weights::

    python tools/analysis_tools/ddp_check.py CONFIG [CONFIG ...] \\
        [--ranks 2] [--iters 2] [--device cuda] [--amp fp16] [--json OUT]

Exit status 1 when a config failed or left parameters without gradient.
"""
import argparse
import json
import sys
from typing import Dict, List

import torch
from mmengine.config import DictAction

from projects.occ_common.analysis.ddp_check import ddp_check


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(
        description='Train configs for a few iterations under DDP.')
    parser.add_argument('configs', nargs='+', help='config files')
    parser.add_argument('--ranks', type=int, default=2,
                        help='processes (GPUs on CUDA)')
    parser.add_argument('--iters', type=int, default=2,
                        help='training iterations (DDP refuses unused '
                        'parameters from the second on)')
    parser.add_argument(
        '--device', choices=('cpu', 'cuda'),
        default='cuda' if torch.cuda.is_available() else 'cpu')
    parser.add_argument('--amp', choices=('fp16', 'bf16'),
                        help='mixed precision (AmpOptimWrapper on CUDA; '
                        'bf16 autocast on the CPU)')
    parser.add_argument('--batch-size', type=int,
                        help='samples per rank (default: the config\'s)')
    parser.add_argument('--num-points', type=int,
                        help='points per synthetic cloud (default: 34,720 '
                        'per merged sweep of the config, nuScenes\' size)')
    parser.add_argument('--json', help='also write the results here')
    parser.add_argument('--cfg-options', nargs='+', action=DictAction,
                        help='overrides applied to every config, key=value')
    args = parser.parse_args(argv)
    if args.ranks < 1 or args.iters < 1:
        parser.error('--ranks and --iters must be at least 1')
    return args


def summarise(results: List[List[Dict]]) -> List[Dict]:
    """One line per config from the per-rank results."""
    rows = []
    for ranks in results:
        first = ranks[0]
        errors = [r['error'] for r in ranks if r['error']]
        row = dict(
            config=first['config'],
            ok=not errors and not any(r['unused'] for r in ranks),
            backend=first.get('backend'),
            error=errors[0] if errors else None,
            unused=sorted({n for r in ranks for n in r['unused']}),
            losses=[r['losses'] for r in ranks],
            iter_s=[r.get('iter_s') for r in ranks],
            max_param_diff_from_rank0=max(
                (r.get('max_param_diff_from_rank0') or 0.0) for r in ranks))
        peaks = [r['peak_memory_mb'] for r in ranks if 'peak_memory_mb' in r]
        if peaks:
            row['peak_memory_mb'] = max(peaks)
        rows.append(row)
    return rows


def main(argv=None) -> int:
    args = parse_args(argv)
    jobs = [
        dict(config=c, options=args.cfg_options, batch_size=args.batch_size)
        for c in args.configs
    ]
    rows = summarise(
        ddp_check(jobs, ranks=args.ranks, iters=args.iters,
                  device_kind=args.device, amp=args.amp,
                  num_points=args.num_points))
    for row in rows:
        state = 'ok' if row['ok'] else 'FAILED'
        print(f'{state:6s} {row["config"]} ({args.ranks} ranks, '
              f'{row["backend"]}, amp {args.amp or "off"})')
        if row['error']:
            print(f'       error: {row["error"].splitlines()[0]}')
        if row['unused']:
            print(f'       no gradient: {", ".join(row["unused"])}')
        if row['losses'][0]:
            last = [f'{v[-1]:.4f}' for v in row['losses'] if v]
            times = row['iter_s'][0] or []
            print(f'       last loss per rank {", ".join(last)}; seconds a '
                  f'step (rank 0) {", ".join(f"{t:.2f}" for t in times)}; '
                  f'max weight difference from rank 0 '
                  f'{row["max_param_diff_from_rank0"]:.3g}')
        if 'peak_memory_mb' in row:
            print(f'       peak CUDA memory {row["peak_memory_mb"]:.0f} MB')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(dict(ranks=args.ranks, iters=args.iters,
                           device=args.device, amp=args.amp, configs=rows),
                      f, indent=1)
    return 0 if all(row['ok'] for row in rows) else 1


if __name__ == '__main__':
    sys.exit(main())
