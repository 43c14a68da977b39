#!/usr/bin/env python
"""Parameters, inference latency and peak memory of a model config.

Like OccCylindrical's Table IV and SDG-OCC's Time column: the model of
``CONFIG`` (weights from ``CKPT`` if given, else as built) predicts one
batch, at the config's input size, ``--warmup`` times untimed and then
``--runs`` times timed; the table gives the median and the spread (std,
min-max, interquartile range) of the latency, wall and process CPU time
(all threads; far less sensitive than wall time to other jobs on a shared
machine). ``--compare CONFIG2`` builds a second model in the same process,
times the two in alternating rounds (each round runs both, in rotating
order, so load drifts hit both alike) and adds the ratio second / first.

Beside latency: the GFLOP of one prediction (``torch.utils.flop_counter``:
matmuls, convolutions, attention; custom sparse/scatter operators count
zero) and the share of the machine's fp32 matmul rate that it achieves
(GFLOP / median wall time / the median rate of a ``--matmul-size`` cube
``torch.mm`` timed in the same rounds as the models, so under the same
load and at the same thread count).
``--keep-freed-memory`` times with glibc keeping freed memory for reuse
(as ``CPUMallocTuningHook`` does for CPU training) instead of faulting
large activations in anew on every call.
``--fuse-conv-bn`` (and ``--channels-last``) time the deploy-time model
whose image backbones' BatchNorms are folded into their convolutions
(:mod:`projects.occ_common.models.deploy`). ``--train`` times one training
iteration instead (``model.train_step`` with the config's
``optim_wrapper``: preprocessing, the loss forward, backward and the
optimiser step), and its peak memory; synthetic batches then carry random
occupancy labels and sparse LiDAR depth maps.
``--compile [MODE]`` times the step under ``torch.compile`` (``test_step``,
or ``train_step`` with ``--train``, as mmengine's ``compile=True`` and
``TorchCompileHook`` compile them; every cloud's point count marked
dynamic; ``reduce-overhead`` replays CUDA graphs on a GPU); compilation
happens in the warm-up, so give it at least one. ``--eager-vs-compiled``
times the config eager and compiled side by side in alternating rounds
(ratio compiled / eager). The GFLOP are counted on the eager step.

What is timed is ``model.test_step(batch)``: the data preprocessor
(normalisation, voxelisation), the forward pass and the prediction
post-processing, as one collated batch leaves the dataloader; file loading
and augmentation are not. The batch is the first of the config's test
dataloader (``--batch-size`` samples, 1 by default as in the papers), or
with ``--synthetic-batch`` random data of the shapes the config declares:
``len(cam_names)`` images of ``img_size``, a LiDAR-like cloud of
``--num-points`` points in ``point_cloud_range`` and a ``grid_size``
label grid, for configs whose data is not at hand.

Peak memory is measured as every benchmark tool does
(:class:`projects.occ_common.analysis.benchmarking.PeakMemory`): on CUDA
``torch.cuda.max_memory_allocated`` during one call, on CPU the process's
resident-set high-water mark. ``forward_memory_mb`` is the part added by
the call, ``peak_memory_mb`` the whole process (or all CUDA tensors; with
``--compare`` both models are resident).

Usage::

    python tools/analysis_tools/benchmark.py CONFIG [CKPT] [--compare \\
        CONFIG2 [CKPT2]]
        [--device cuda] [--runs 20] [--warmup 5] [--json OUT]

Like the train and test tools this script takes the models from the
configs' ``custom_imports``; it imports only the shared benchmark helpers.
"""
import argparse
import copy
import json
import os
import os.path as osp
from typing import Callable, Dict, List, Optional, Tuple

import torch
from mmengine.config import Config, DictAction

from projects.occ_common.analysis.benchmarking import (PeakMemory,
                                                       alternating_runs,
                                                       count_gflop,
                                                       matmul_call,
                                                       matmul_share, summarise)
from projects.occ_common.engine.config_checks import (cfg_errors_exit,
                                                      merge_cfg_options)
from projects.occ_common.engine.hooks.torch_compile_hook import \
    mark_dynamic_points
from projects.occ_common.synthetic.synthetic_batch import (
    NUSCENES_SWEEP_POINTS, synthetic_batch)
from projects.occ_common.utils.glibc_malloc import (MMAP_THRESHOLD,
                                                    TRIM_THRESHOLD,
                                                    tune_glibc_malloc)

#: ``torch.compile`` modes of ``--compile`` ('default': no mode given).
COMPILE_MODES = ('default', 'reduce-overhead', 'max-autotune',
                 'max-autotune-no-cudagraphs')


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(
        description='Benchmark parameters, latency and memory of configs.')
    parser.add_argument('config', help='config file')
    parser.add_argument('checkpoint', nargs='?', help='checkpoint file')
    parser.add_argument(
        '--compare',
        nargs='+',
        metavar=('CONFIG2', 'CKPT2'),
        help='a second config (and checkpoint) to run side by side')
    parser.add_argument(
        '--device',
        default='cuda' if torch.cuda.is_available() else 'cpu',
        help='cpu or cuda[:i] (default: cuda if available)')
    parser.add_argument('--warmup', type=int, default=3)
    parser.add_argument('--runs', type=int, default=10)
    parser.add_argument(
        '--batch-size', type=int, default=1, help='samples per batch')
    parser.add_argument(
        '--synthetic-batch',
        action='store_true',
        help='random inputs of the config\'s shapes instead of its test '
        'data')
    parser.add_argument(
        '--num-points',
        type=int,
        help='points per synthetic cloud (default: one nuScenes sweep of '
        f'{NUSCENES_SWEEP_POINTS} points per merged sweep of the config)')
    parser.add_argument(
        '--threads', type=int, help='torch CPU threads (default: torch\'s)')
    parser.add_argument(
        '--keep-freed-memory',
        action='store_true',
        help='glibc keeps freed memory for reuse instead of returning it to '
        'the kernel and faulting it in again (what CPUMallocTuningHook does '
        'for CPU training; projects/occ_common/utils/glibc_malloc.py)')
    parser.add_argument(
        '--fuse-conv-bn',
        action='store_true',
        help='fold the image backbones\' BatchNorms into their convolutions '
        '(inference only; projects/occ_common/models/deploy.py)')
    parser.add_argument(
        '--channels-last',
        action='store_true',
        help='with --fuse-conv-bn: also store the backbones\' weights '
        'channels-last')
    parser.add_argument(
        '--train',
        action='store_true',
        help='time one training iteration (train_step: loss, backward, '
        'optimiser step) instead of a prediction')
    parser.add_argument(
        '--compile',
        nargs='?',
        const='default',
        choices=COMPILE_MODES,
        help='time the step under torch.compile with this mode (default: '
        "'default'; 'reduce-overhead' replays CUDA graphs on a GPU); with "
        '--compare both models')
    parser.add_argument(
        '--eager-vs-compiled',
        action='store_true',
        help='time CONFIG eager and compiled (--compile\'s mode) side by '
        'side in alternating rounds; the ratio is compiled / eager')
    parser.add_argument(
        '--matmul-size',
        type=int,
        default=2048,
        help='side of the fp32 torch.mm whose rate is the reference of the '
        '"share of matmul rate" (0: skip)')
    parser.add_argument('--json', help='also write the results here')
    parser.add_argument(
        '--cfg-options',
        nargs='+',
        action=DictAction,
        help='overrides applied to every config, key=value')
    args = parser.parse_args(argv)
    if args.compare is not None and len(args.compare) > 2:
        parser.error('--compare takes CONFIG2 and an optional CKPT2.')
    if args.channels_last and not args.fuse_conv_bn:
        parser.error('--channels-last goes with --fuse-conv-bn.')
    if args.train and args.fuse_conv_bn:
        parser.error('--fuse-conv-bn is inference only; not with --train.')
    if args.eager_vs_compiled and args.compare is not None:
        parser.error('--eager-vs-compiled compares CONFIG with itself; not '
                     'with --compare.')
    if (args.compile or args.eager_vs_compiled) and args.warmup < 1:
        parser.error('--compile compiles in the warm-up: --warmup >= 1.')
    if args.runs < 1 or args.warmup < 0 or args.batch_size < 1:
        parser.error('expected --runs >= 1, --warmup >= 0, --batch-size '
                     '>= 1.')
    return args


def load_config(path: str, options: Optional[dict]) -> Config:
    """Read a config (importing its plugins) and apply the overrides."""
    from mmengine.registry import init_default_scope
    cfg = Config.fromfile(path)
    merge_cfg_options(cfg, options)
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    return cfg


def test_batch(cfg: Config, batch_size: int) -> Tuple[dict, str]:
    """The first batch of the config's test dataloader."""
    from mmengine.runner import Runner
    loader_cfg = copy.deepcopy(cfg.test_dataloader)
    loader_cfg.update(batch_size=batch_size, num_workers=0,
                      persistent_workers=False)
    loader = Runner.build_dataloader(loader_cfg)
    batch = next(iter(loader))
    return batch, f'first test batch of {type(loader.dataset).__name__}'


def predict_once(model: torch.nn.Module, data: dict,
                 device: torch.device) -> None:
    """One timed call: ``test_step`` without autograd, synchronised."""
    with torch.no_grad():
        model.test_step(data)
    if device.type == 'cuda':
        torch.cuda.synchronize(device)


def train_once(model: torch.nn.Module, data: dict, optim_wrapper,
               device: torch.device) -> None:
    """One timed training iteration: ``train_step``, synchronised."""
    model.train_step(data, optim_wrapper)
    if device.type == 'cuda':
        torch.cuda.synchronize(device)


class Subject:
    """One model under test: built, loaded, with its batch.

    Args:
        config (str): Config file.
        checkpoint (str, optional): Weights to load.
        args (argparse.Namespace): The command line.
        compile_mode (str, optional): ``torch.compile`` the timed step
            with this mode (:data:`COMPILE_MODES`). Defaults to None
            (eager).
    """

    def __init__(self, config: str, checkpoint: Optional[str], args,
                 compile_mode: Optional[str] = None) -> None:
        from projects.occ_common.apis import init_model
        cfg = load_config(config, args.cfg_options)
        self.config, self.checkpoint = config, checkpoint
        self.device = torch.device(args.device)
        # Checked as tools/test.py checks: a checkpoint of another model
        # is refused instead of timing random weights.
        self.model = init_model(cfg, checkpoint or None, args.device)
        self.train = args.train
        self.optim_wrapper = None
        if self.train:
            from mmengine.optim import build_optim_wrapper
            self.model.train()
            self.optim_wrapper = build_optim_wrapper(self.model,
                                                     cfg.optim_wrapper)
        else:
            self.model.eval()
        self.folded_bn = 0
        if args.fuse_conv_bn:
            import projects.occ_common.models.deploy as deploy
            self.folded_bn = deploy.fuse_backbone_conv_bn(
                self.model, channels_last=args.channels_last)
        self.compile_mode = compile_mode
        if compile_mode is not None:
            step = 'train_step' if self.train else 'test_step'
            setattr(self.model, step, torch.compile(
                getattr(self.model, step),
                mode=None if compile_mode == 'default' else compile_mode))
        if args.synthetic_batch:
            self.batch, self.described = synthetic_batch(
                cfg, args.batch_size, args.num_points, labels=args.train)
        else:
            self.batch, self.described = test_batch(cfg, args.batch_size)
        self._data = None

    def fresh_input(self) -> None:
        """A fresh copy of the batch: ``test_step`` writes into it."""
        self._data = copy.deepcopy(self.batch)
        if self.compile_mode is not None:
            mark_dynamic_points(self._data)

    def predict(self) -> None:
        """One prediction (with ``--train`` one training iteration) on the
        input :meth:`fresh_input` made."""
        if self.train:
            train_once(self.model, self._data, self.optim_wrapper,
                       self.device)
        else:
            predict_once(self.model, self._data, self.device)

    def static_report(self) -> Dict:
        """Parameters, GFLOP and peak memory of one prediction."""
        self.fresh_input()
        with torch.compiler.set_stance('force_eager'):
            gflop = count_gflop(self.predict)
        self.fresh_input()
        with PeakMemory(self.device) as memory:
            self.predict()
        params = sum(p.numel() for p in self.model.parameters())
        trainable = sum(p.numel() for p in self.model.parameters()
                        if p.requires_grad)
        return dict(
            config=self.config,
            checkpoint=self.checkpoint,
            model=type(self.model).__name__,
            input=self.described,
            batch_size=self.batch_size,
            params=params,
            trainable_params=trainable,
            gflop=gflop,
            mode='train' if self.train else 'predict',
            compiled=self.compile_mode,
            folded_bn=self.folded_bn,
            peak_memory_mb=memory.peak_bytes / 2**20,
            forward_memory_mb=memory.added_bytes / 2**20,
            memory_kind=memory.kind)

    @property
    def batch_size(self) -> int:
        return len(self.batch['data_samples'])


def benchmark_models(subjects: List[Subject],
                     args) -> Tuple[List[Dict], Optional[Dict]]:
    """Static figures of each model, then latency in alternating rounds.

    With ``args.matmul_size`` a fp32 ``torch.mm`` runs in every round too,
    so that the matmul rate the shares refer to is measured under the
    same load as the models (on a shared machine a rate measured once,
    before the models, moved by 1.5x within minutes: 2026-11-25,
    ccd4029).

    Args:
        subjects (list[Subject]): One or two models.
        args (argparse.Namespace): ``runs``, ``warmup``, ``device``,
            ``matmul_size`` (0: no matmul reference).

    Returns:
        tuple: One result per model, and the matmul rate (GFLOP/s) of the
        rounds as :func:`summarise` gives it (None without a reference).
    """
    results = [subject.static_report() for subject in subjects]
    names = [str(i) for i in range(len(subjects))]
    calls = {n: s.predict for n, s in zip(names, subjects)}
    if args.matmul_size:
        calls['matmul'], mm_gflop = matmul_call(args.matmul_size,
                                                device=args.device)
    times = alternating_runs(
        calls, rounds=args.runs, warmup=args.warmup, device=args.device,
        before={n: s.fresh_input for n, s in zip(names, subjects)})
    rate = (summarise([mm_gflop / t for t in times['matmul']['wall_s']])
            if args.matmul_size else None)
    for name, result in zip(names, results):
        wall = [t * 1000 for t in times[name]['wall_s']]
        result['latency_ms'] = summarise(wall)
        result['cpu_ms'] = summarise([t * 1000
                                      for t in times[name]['cpu_s']])
        result['matmul_share'] = (None if rate is None else matmul_share(
            result['gflop'], result['latency_ms']['median'] / 1000,
            rate['median']))
    return results, rate


def ratios(first: Dict, second: Dict) -> Dict[str, Optional[float]]:
    """second / first of params, GFLOP, median latency (wall and CPU) and
    forward memory.

    A ratio whose denominator is 0 (or a forward memory under 1 MB) is
    None.
    """

    def ratio(a: float, b: float, least: float = 0.0) -> Optional[float]:
        return b / a if a > least else None

    return dict(
        params=ratio(first['params'], second['params']),
        latency_median=ratio(first['latency_ms']['median'],
                             second['latency_ms']['median']),
        cpu_median=ratio(first['cpu_ms']['median'],
                         second['cpu_ms']['median']),
        gflop=ratio(first['gflop'], second['gflop']),
        # Below 1 MB the RSS measure is page-level noise.
        forward_memory=ratio(first['forward_memory_mb'],
                             second['forward_memory_mb'], least=1.0))


def format_table(report: Dict) -> str:
    """The results as a fixed-width table."""
    models = report['models']
    rows: List[Tuple[str, Callable[[Dict], str]]] = [
        ('model', lambda r: r['model']),
        ('timed call', lambda r: r['mode']),
        ('torch.compile', lambda r: r.get('compiled') or 'no'),
        ('params', lambda r: f'{r["params"]:,}'),
        ('latency median (ms)', lambda r: f'{r["latency_ms"]["median"]:.2f}'),
        ('latency std (ms)', lambda r: f'{r["latency_ms"]["std"]:.2f}'),
        ('latency min-max (ms)', lambda r:
         f'{r["latency_ms"]["min"]:.2f}-{r["latency_ms"]["max"]:.2f}'),
        ('latency IQR (ms)', lambda r:
         f'{r["latency_ms"]["p25"]:.2f}-{r["latency_ms"]["p75"]:.2f}'),
        ('CPU time median (ms)', lambda r: f'{r["cpu_ms"]["median"]:.2f}'),
        ('GFLOP', lambda r: f'{r["gflop"]:.3f}'),
        ('folded BatchNorms', lambda r: str(r['folded_bn'])),
        ('share of matmul rate', lambda r: '' if r['matmul_share'] is None
         else f'{100 * r["matmul_share"]:.1f} %'),
        ('forward memory (MB)', lambda r: f'{r["forward_memory_mb"]:.1f}'),
        ('peak memory (MB)', lambda r: f'{r["peak_memory_mb"]:.1f}'),
    ]
    names = [osp.splitext(osp.basename(r['config']))[0] for r in models]
    ratio_of = {'params': 'params', 'latency median (ms)':
                'latency_median', 'CPU time median (ms)': 'cpu_median',
                'GFLOP': 'gflop', 'forward memory (MB)': 'forward_memory'}
    header = ['', *names] + (['ratio 2/1'] if 'ratio' in report else [])
    lines = [header]
    for label, cell in rows:
        line = [label, *(cell(r) for r in models)]
        if 'ratio' in report:
            value = report['ratio'].get(ratio_of.get(label, ''), None)
            line.append('' if value is None else f'{value:.3f}')
        lines.append(line)
    widths = [max(len(line[i]) for line in lines) for i in range(len(header))]
    text = [
        '  '.join(c.ljust(w) if i == 0 else c.rjust(w)
                  for i, (c, w) in enumerate(zip(line, widths)))
        for line in lines
    ]
    for r in models:
        runs = len(r['latency_ms']['runs'])
        text.append(f'{osp.basename(r["config"])}: {r["input"]}, batch '
                    f'{r["batch_size"]}, {report["device"]}, '
                    f'{report["threads"]} threads, malloc '
                    f'{report.get("malloc", "default")}, {runs} runs after '
                    f'{report["warmup"]} warm-up' +
                    (', alternating rounds' if len(models) > 1 else ''))
    if report.get('matmul_gflops'):
        rounds = report.get('matmul_gflops_rounds') or {}
        spread = (f' (min-max {rounds["min"]:.1f}-{rounds["max"]:.1f})'
                  if rounds else '')
        text.append(f'matmul rate (fp32 {report["matmul_size"]}^3 torch.mm, '
                    f'same process and threads, median of the rounds it '
                    f'alternated with the models): '
                    f'{report["matmul_gflops"]:.1f}{spread} GFLOP/s')
    return '\n'.join(text)


def main(argv=None) -> Dict:
    """Run the benchmark; print the table and return the report."""
    args = parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    malloc = 'default'
    if args.keep_freed_memory:
        malloc = ('keeps freed memory' if tune_glibc_malloc(
            MMAP_THRESHOLD, TRIM_THRESHOLD) else 'unchanged (not glibc)')
    mode = args.compile or ('default' if args.eager_vs_compiled else None)
    subjects = [
        Subject(args.config, args.checkpoint, args,
                None if args.eager_vs_compiled else mode)
    ]
    if args.compare:
        subjects.append(
            Subject(args.compare[0], (args.compare[1:] or [None])[0], args,
                    mode))
    elif args.eager_vs_compiled:
        subjects.append(Subject(args.config, args.checkpoint, args, mode))
    models, rate = benchmark_models(subjects, args)
    report = dict(
        device=args.device,
        threads=torch.get_num_threads(),
        malloc=malloc,
        warmup=args.warmup,
        torch=torch.__version__,
        matmul_size=args.matmul_size,
        matmul_gflops=None if rate is None else rate['median'],
        matmul_gflops_rounds=rate,
        models=models)
    if len(subjects) > 1:
        report['ratio'] = ratios(*report['models'])
    print(format_table(report))
    if args.json:
        folder = osp.dirname(osp.abspath(args.json))
        os.makedirs(folder, exist_ok=True)
        with open(args.json, 'w') as f:
            json.dump(report, f, indent=2)
        print(f'wrote {args.json}')
    return report


if __name__ == '__main__':
    with cfg_errors_exit():
        main()
