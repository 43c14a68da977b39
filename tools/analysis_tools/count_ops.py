"""Count the kernel launches and host syncs of a prediction or a training
step, per top-level module, at a config's input size.

Runs on any device (the CPU counts what a GPU would launch: see
:mod:`projects.occ_common.analysis.op_counting`; where the CPU and GPUs take
different code paths, the GPU's is counted unless ``--cpu-path``, see
:mod:`projects.occ_common.utils.device_path`): builds the config's model,
runs one warm-up call (caches fill, as in a long run), then one counted
prediction (``test_step``) or training step (``train_step`` with the
config's optimiser: forward, backward and the step) on the benchmark's
synthetic batch, for each ``--batch`` size::

    python tools/analysis_tools/count_ops.py CONFIG [--train] [--batch 1 2] \\
        [--num-points N] [--device cpu] [--cpu-path] [--json OUT] \\
        [--cfg-options ...]
"""
import argparse
import copy
import json
from typing import Dict, List

import torch
from mmengine.config import DictAction

from projects.occ_common.analysis.op_counting import OpCounter
from projects.occ_common.engine.config_checks import (cfg_errors_exit,
                                                      merge_cfg_options)
from projects.occ_common.synthetic.synthetic_batch import synthetic_batch
from projects.occ_common.utils.device_path import forced_accelerator_path


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(
        description='Count kernel launches and host syncs of a config.')
    parser.add_argument('config', help='config file')
    parser.add_argument('--train', action='store_true',
                        help='count a training step instead of a '
                        'prediction')
    parser.add_argument('--batch', type=int, nargs='+', default=[1],
                        help='batch sizes counted (default: 1)')
    parser.add_argument('--num-points', type=int,
                        help='points per synthetic cloud (default: 34,720 '
                        'per merged sweep of the config)')
    parser.add_argument('--device', default='cpu',
                        help='where the counted call runs (default cpu)')
    parser.add_argument('--cpu-path', action='store_true',
                        help='count the CPU\'s code path where it differs '
                        '(row blocks, rulebook loops); by default the path '
                        'a GPU takes is counted, on any device')
    parser.add_argument('--json', help='also write the counts here')
    parser.add_argument('--cfg-options', nargs='+', action=DictAction,
                        help='overrides, key=value')
    args = parser.parse_args(argv)
    if min(args.batch) < 1:
        parser.error('--batch sizes must be at least 1')
    return args


def count_call(model, cfg, batch: dict, train: bool,
               foreach: bool = False) -> OpCounter:
    """One warm-up call, then one counted call of the same batch.

    ``foreach``: the optimiser and the gradient clipping use torch's
    multi-tensor (foreach) kernels, what torch picks by default for CUDA
    parameters; on CPU parameters it picks one kernel per tensor (and an
    ``.item()`` of each step count), which a GPU never runs.
    """
    optim_wrapper = None
    if train:
        from mmengine.optim import build_optim_wrapper
        optim_cfg = copy.deepcopy(cfg.optim_wrapper)
        if foreach:
            optim_cfg.optimizer.setdefault('foreach', True)
            if optim_cfg.get('clip_grad'):
                optim_cfg.clip_grad.setdefault('foreach', True)
        optim_wrapper = build_optim_wrapper(model, optim_cfg)
        model.train()
    else:
        model.eval()

    def call():
        data = copy.deepcopy(batch)
        if train:
            model.train_step(data, optim_wrapper)
        else:
            with torch.no_grad():
                model.test_step(data)

    call()
    counter = OpCounter(model)
    if optim_wrapper is not None:
        step = optim_wrapper.optimizer.step

        def counted_step(*args, **kwargs):
            with counter.optimizer_step():
                return step(*args, **kwargs)

        optim_wrapper.optimizer.step = counted_step
    with counter:
        call()
    return counter


def count(model, cfg, batch: dict, train: bool,
          cpu_path: bool) -> OpCounter:
    """:func:`count_call` on the GPU's code path unless ``cpu_path``
    (:mod:`projects.occ_common.utils.device_path`)."""
    if cpu_path:
        return count_call(model, cfg, batch, train)
    with forced_accelerator_path():
        return count_call(model, cfg, batch, train, foreach=True)


def format_rows(rows: List[Dict]) -> str:
    """The per-(module, phase) table."""
    lines = [f'{"module":28s} {"phase":9s} {"launches":>9s} {"syncs":>6s} '
             f'{"host":>5s}  top operators']
    for row in rows:
        top = ', '.join(f'{k} {v}' for k, v in row['top_ops'].items())
        lines.append(f'{row["module"]:28s} {row["phase"]:9s} '
                     f'{row["launches"]:9d} {row["syncs"]:6d} '
                     f'{row["host_data"]:5d}  {top}')
    return '\n'.join(lines)


def main(argv=None) -> Dict:
    args = parse_args(argv)
    from mmdet3d.registry import MODELS
    from mmengine.config import Config
    from mmengine.registry import init_default_scope
    with cfg_errors_exit():
        cfg = Config.fromfile(args.config)
        merge_cfg_options(cfg, args.cfg_options)
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    device = torch.device(args.device)
    torch.manual_seed(0)
    model = MODELS.build(cfg.model).to(device)
    report = dict(config=args.config, mode='train' if args.train else
                  'predict', device=str(device),
                  path='cpu' if args.cpu_path else 'gpu', batches={})
    for size in args.batch:
        batch, described = synthetic_batch(cfg, size, args.num_points,
                                           labels=args.train)
        counter = count(model, cfg, batch, args.train, args.cpu_path)
        rows, totals = counter.table(), counter.totals()
        report['batches'][size] = dict(input=described, totals=totals,
                                       rows=rows)
        print(f'{report["mode"]}, batch {size} ({described}): '
              f'{totals["launches"]} launches, {totals["syncs"]} syncs, '
              f'{totals["host_data"]} host-data tensors')
        print(format_rows(rows))
    if len(args.batch) > 1:
        first = report['batches'][args.batch[0]]['totals']
        for size in args.batch[1:]:
            other = report['batches'][size]['totals']
            print(f'batch {size} / batch {args.batch[0]}: launches '
                  f'{other["launches"] / max(first["launches"], 1):.2f}x, '
                  f'syncs {other["syncs"] / max(first["syncs"], 1):.2f}x')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(report, f, indent=1)
    return report


if __name__ == '__main__':
    main()
