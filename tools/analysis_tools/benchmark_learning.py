"""Do the models learn? Train configs on synthetic scenes, evaluate on
held-out ones, and draw their learning curves.

    python tools/analysis_tools/benchmark_learning.py --runs occcyl-tiny \\
        sdg-fusion-tiny \\
        --iters 400 --val-interval 100 --out work_dirs/learning

1. generates (or reuses) a synthetic nuScenes-format world whose last
   ``--val-scenes`` scenes are the val split (other layouts; the scenes
   cycle through clear, rainy night, rain and night, so with the default
   10 scenes the held-out clear day and rainy night also light two
   training scenes each) and converts it with
   ``tools/create_data.py``;
2. trains every named run with ``tools/train.py``'s machinery for a fixed
   budget (``--iters``, or the config's own schedule, optionally capped by
   ``--max-minutes`` of training time), validating on the held-out scenes
   every ``--val-interval`` iterations;
3. evaluates the last checkpoint with ``tools/test.py --show-dir`` (a few
   pictures of prediction against ground truth per run);
4. writes ``runs/<name>/curve.png`` (validation IoU / mIoU and training
   loss against iterations) and ``results.md`` / ``results.json`` (IoU,
   mIoU, per-class IoU, train time, iterations, and where the classes
   under IoU 10 put their voxels, from ``runs/<name>/confusion.csv``) of
   every finished run in ``--out``.

It resumes: a killed run continues from its last checkpoint, and a finished
run (``runs/<name>/result.json`` with the same settings) is reused; with
``--extend`` a run that its time budget stopped continues under a larger
one, where its learning-rate schedule left off. Nothing
here is CPU-specific: the Runner trains on a GPU when there is one.
Training happens in a child process (``--train-one``) so that every run
gets a fresh Runner, logger and registry state.
"""
import argparse
import copy
import glob
import json
import math
import os
import os.path as osp
import sys
import time
from typing import Dict, List, Optional

from mmengine import Config

from projects.occ_common.analysis.tool_runs import (LARGE_CLASS_MIN_IOU,
                                                    LARGE_CLASS_VOXELS,
                                                    data_options, format_table,
                                                    large_classes,
                                                    last_metrics, load_tool,
                                                    occupancy_metric, pct,
                                                    prepare_world,
                                                    read_json_lines, run,
                                                    scene_names,
                                                    stretched_times, tool,
                                                    train_label_options)
from projects.occ_common.evaluation import (largest_confusions,
                                            read_confusion_csv)

#: The camera-only LSS baseline of SDG-OCC's Table 3 as --cfg-options of
#: an SDG-Fusion config (the deltas of configs/sdg_occ/ablations/
#: sdgocc-camera-lss_*).
_CAMERA_LSS = [
    'model.lidar_encoder=None', 'model.fusion=None',
    'model.view_transform.use_sdg=False', 'model.depth_net.seg_channels=0',
    'model.loss_seg=None'
]
#: SDG-OCC Table 3's "+SDG" row (configs/sdg_occ/ablations/
#: sdgocc-camera-sdg_*): the SDG lift without the LiDAR branch.
_CAMERA_SDG = ['model.lidar_encoder=None', 'model.fusion=None']
#: SDG-KL trained with three losses (SDGOcc's kl_losses='three_loss'), as
#: the SDG-KL configs were before 2026-11-28.
_THREE_LOSS = [
    'model.kl_losses=three_loss', 'model.separate_teacher_head=True'
]
#: Named runs: name -> (config, extra --cfg-options).
RUNS = {
    'occcyl-tiny': ('configs/occ_cyl/'
                    'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py', []),
    'sdg-fusion-tiny': ('configs/sdg_occ/'
                        'sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py',
                        []),
    'sdg-kl-tiny': ('configs/sdg_occ/'
                    'sdgocc-kl_tiny_1xb1-6e_occ3d-nus-synthetic.py', []),
    # The ablation rows at tiny size: the same deltas as
    # configs/occ_cyl/ablations/occcyl-nodepthsup_* (Table V) and
    # _CAMERA_LSS.
    'occcyl-tiny-nodepthsup': ('configs/occ_cyl/occcyl_tiny_1xb1-6e_'
                               'surroundocc-nus-synthetic.py',
                               ['model.loss_depth=None']),
    'sdg-camera-lss-tiny': ('configs/sdg_occ/sdgocc-fusion_tiny_1xb1-6e_'
                            'occ3d-nus-synthetic.py', _CAMERA_LSS),
}
# The small configs (the paper's modules at widths and resolutions two CPU
# cores train in under an hour) and the same ablation rows.
_OCC_SMALL = ('configs/occ_cyl/'
              'occcyl_small_1xb1-12e_surroundocc-nus-synthetic.py')
_OCC_SMALL_SEG2D = ('configs/occ_cyl/'
                    'occcyl-seg2d_small_1xb1-12e_surroundocc-nus-synthetic.py')
_SDG_SMALL = 'configs/sdg_occ/sdgocc-{}_small_1xb1-20e_occ3d-nus-synthetic.py'
_SDG_SMALL_NOMASK = _SDG_SMALL.replace('-nus-', '-nus-nomask-')
RUNS.update({
    'occcyl-small': (_OCC_SMALL, []),
    'occcyl-small-nodepthsup': (_OCC_SMALL, ['model.loss_depth=None']),
    # On Occ3D labels without the camera mask, scored with RayIoU beside
    # the camera-mask mIoU.
    'occcyl-small-occ3d-nomask': (_OCC_SMALL.replace(
        'surroundocc-nus', 'occ3d-nus-nomask'), []),
    # A cylinder of twice the small config's radial and angular cells:
    # the held-out ground truth kept at the majority class of each cell
    # scores 89.5 mIoU on it against 69.3 on 64 x 128 x 16.
    'occcyl-small-cyl128': (_OCC_SMALL,
                            ['model.cylinder.shape=[128,256,16]']),
    # Not in the paper: SDG-OCC's 2-D semantic target for the image branch
    # (the config's header says why), with and without depth supervision.
    'occcyl-small-seg2d': (_OCC_SMALL_SEG2D, []),
    'occcyl-small-seg2d-nodepthsup': (_OCC_SMALL_SEG2D,
                                      ['model.loss_depth=None']),
    # ... and with the scene turned by a random multiple of 90 degrees
    # (OccBEVAug, exact on the square grid; index 7 of the training
    # pipeline), against the layout prior of 8 training scenes whose main
    # road all runs along the driving direction. On 2026-11-27
    # (2e56599): 73.44 / 37.48 and 72.06 / 36.27 IoU / mIoU (seeds 0, 1)
    # against 74.58 / 38.41 and 73.20 / 38.88 without, and the held-out
    # cross streets no more often driveable (24.0 and 35.9 % against
    # 20.8 and 38.2 %).
    'occcyl-small-seg2d-nodepthsup-rot90': (
        _OCC_SMALL_SEG2D, [
            'model.loss_depth=None',
            'train_dataloader.dataset.pipeline.7.rot90=True'
        ]),
    'sdg-fusion-small': (_SDG_SMALL.format('fusion'), []),
    # SDG-KL as Sec. 3.5 writes it (kl_losses='paper', the config's):
    # one occupancy loss on the fused BEV through the one head, plus FOAD.
    'sdg-kl-small': (_SDG_SMALL.format('kl'), []),
    # ... distilling standardised features (FOADDistillLoss's docstring:
    # eq. 8 on the raw ones pulled 4-27x harder than the occupancy loss
    # at initialisation).
    'sdg-kl-small-norm': (_SDG_SMALL.format('kl'),
                          ['model.loss_distill.normalize=channel']),
    # The SDG-KL configs' form before 2026-11-28: the camera BEV's own
    # occupancy loss, the teacher's through its own head, and FOAD.
    'sdg-kl-small-threeloss': (_SDG_SMALL.format('kl'), _THREE_LOSS),
    'sdg-kl-small-threeloss-norm': (
        _SDG_SMALL.format('kl'),
        _THREE_LOSS + ['model.loss_distill.normalize=channel']),
    # Trained without the camera mask, scored with RayIoU beside the
    # camera-mask mIoU.
    'sdg-fusion-small-nomask': (_SDG_SMALL_NOMASK.format('fusion'), []),
    'sdg-kl-small-nomask': (_SDG_SMALL_NOMASK.format('kl'), []),
    'sdg-camera-lss-small': (_SDG_SMALL.format('fusion'), _CAMERA_LSS),
    'sdg-camera-sdg-small': (_SDG_SMALL.format('fusion'), _CAMERA_SDG),
    # The three-loss SDG-KL whose teacher decodes with the student's BEV
    # encoder and head.
    'sdg-kl-small-sharedhead': (_SDG_SMALL.format('kl'),
                                ['model.kl_losses=three_loss']),
    # ... and whose teacher's loss does not reach the camera branch.
    'sdg-kl-small-sharedhead-detachcam': (
        _SDG_SMALL.format('kl'), [
            'model.kl_losses=three_loss',
            'model.detach_teacher_camera=True'
        ]),
})
#: Files of a run folder.
RESULT, SETTINGS, CLOCK = 'result.json', 'settings.json', 'train_clock.json'
#: The test's confusion matrix in a run folder (OccupancyMetric's CSV).
CONFUSION = 'confusion.csv'


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        '--runs', nargs='+', default=[], metavar='NAME',
        help=f'named runs: {", ".join(RUNS)}')
    parser.add_argument(
        '--config', nargs=2, action='append', default=[],
        metavar=('NAME', 'CONFIG'), help='an extra run of any config')
    parser.add_argument('--out', default='work_dirs/benchmark_learning',
                        help='output folder (runs, table, curves)')
    parser.add_argument(
        '--data-root', default=None,
        help='synthetic world to use or generate (default: OUT/world)')
    parser.add_argument('--scenes', type=int, default=10)
    parser.add_argument('--val-scenes', type=int, default=2,
                        help='the last N scenes are held out for val')
    parser.add_argument('--samples', type=int, default=8,
                        help='key frames per scene')
    parser.add_argument('--image-size', type=int, nargs=2,
                        default=[480, 270], metavar=('W', 'H'))
    parser.add_argument('--seed', type=int, default=0, help='world seed')
    parser.add_argument(
        '--iters', type=int, default=None,
        help='training iterations per run (default: the config\'s own '
        'schedule); a config\'s LR schedule is stretched to fit')
    parser.add_argument('--val-interval', type=int, default=100,
                        help='validate every N iterations')
    parser.add_argument('--max-minutes', type=float, default=None,
                        help='stop a run after this much training time '
                        '(validation excluded); it then counts as finished')
    parser.add_argument(
        '--max-cpu-minutes', type=float, default=None,
        help='stop a run after this much training CPU time (all threads, '
        'validation excluded): a budget that does not shrink when other '
        'jobs share the machine')
    parser.add_argument('--log-interval', type=int, default=10,
                        help='log the training loss every N iterations')
    parser.add_argument('--pictures', type=int, default=3,
                        help='prediction pictures per run (0: none)')
    parser.add_argument(
        '--cfg-options', nargs='+', default=[], metavar='KEY=VALUE',
        help='overrides applied to every run (part of its settings)')
    parser.add_argument(
        '--train-labels', metavar='DIR',
        help='train on the labels under DIR (gts/, nuscenes_occ/ of the '
        'same world, e.g. from tools/dataset_converters/'
        'generate_occupancy.py) instead of the world\'s own; validation '
        'and test keep the world\'s labels (part of the run\'s settings)')
    parser.add_argument(
        '--suffix', default='',
        help='appended to every run name, e.g. to keep a variant made with '
        '--cfg-options beside the original ("--suffix -bs4" works too)')
    parser.add_argument(
        '--retest', action='store_true',
        help='test the last checkpoint of finished runs again (e.g. after '
        'a change of the metric) instead of reusing their results')
    parser.add_argument(
        '--extend', action='store_true',
        help='continue runs that their time budget stopped, with the '
        '--max-minutes / --max-cpu-minutes given now (larger, or none); '
        'every other setting must be the run\'s own. The stopped run\'s '
        'result is kept as result-<iterations>it.json')
    parser.add_argument(
        '--train-one', metavar='SPEC_JSON', help=argparse.SUPPRESS)
    argv = list(sys.argv[1:] if argv is None else argv)
    # A suffix usually starts with a dash ("-bs4"), which argparse would
    # read as an option and refuse; join it to its flag first. A word that
    # starts with "--" stays an option: "--suffix --retest" is still an
    # error, not a suffix.
    for i in range(len(argv) - 1):
        if argv[i] == '--suffix' and not argv[i + 1].startswith('--'):
            argv[i:i + 2] = [f'--suffix={argv[i + 1]}']
            break
    args = parser.parse_args(argv)
    if not args.train_one and not (args.runs or args.config):
        parser.error('name at least one run (--runs / --config)')
    unknown = sorted(set(args.runs) - set(RUNS))
    if unknown:
        parser.error(f'unknown runs {unknown}; known: {sorted(RUNS)}')
    return args


# ----------------------------------------------------------------------
# The child process: one training run through tools/train.py's machinery.
# ----------------------------------------------------------------------
def set_iteration_budget(cfg, max_iters: Optional[int], val_interval: int,
                         epoch_length: int, log_interval: int) -> int:
    """Make ``cfg`` train ``max_iters`` iterations, validating every
    ``val_interval`` and checkpointing at each validation.

    An epoch-based loop becomes an ``IterBasedTrainLoop``. Every parameter
    scheduler is rewritten in iterations and stretched by ``max_iters`` /
    the config's planned iterations, so that a shorter budget still runs
    the whole schedule (warm-up, decay) in proportion.

    Args:
        cfg (Config): The training config, modified in place.
        max_iters (int, optional): Budget. None keeps the config's own
            schedule length.
        val_interval (int): Validate (and checkpoint) every N iterations.
        epoch_length (int): Iterations per epoch of the train dataloader.
        log_interval (int): Log (and average) the loss every N iterations.

    Returns:
        int: The iteration budget.
    """
    loop = cfg.train_cfg
    if loop.get('type') == 'IterBasedTrainLoop':
        planned = int(loop['max_iters'])
    elif 'max_epochs' in loop:
        planned = int(loop['max_epochs']) * epoch_length
    else:
        raise ValueError(f'benchmark_learning: cannot tell the length of '
                         f'train_cfg {dict(loop)}')
    max_iters = planned if max_iters is None else int(max_iters)
    factor = max_iters / planned
    schedulers = cfg.get('param_scheduler') or []
    if isinstance(schedulers, dict):
        schedulers = [schedulers]
    converted = []
    for scheduler in schedulers:
        scheduler = copy.deepcopy(dict(scheduler))
        unit = epoch_length if scheduler.get('by_epoch', True) else 1
        scheduler.update(stretched_times(scheduler, unit * factor))
        scheduler['by_epoch'] = False
        scheduler.pop('convert_to_iter_based', None)
        converted.append(scheduler)
    cfg.param_scheduler = converted
    cfg.train_cfg = dict(
        type='IterBasedTrainLoop', max_iters=max_iters,
        val_interval=val_interval)
    cfg.default_hooks.checkpoint.update(
        interval=val_interval, by_epoch=False, save_last=True,
        max_keep_ckpts=2)
    cfg.default_hooks.logger.update(
        interval=log_interval, log_metric_by_epoch=False)
    cfg.log_processor = dict(
        type='LogProcessor', window_size=log_interval, by_epoch=False)
    return max_iters


def _initial_val_hook():
    """A hook that validates the untrained model: iteration 0 of the curve.

    It runs last among the ``before_train`` hooks: the weights are
    initialised by then, and every hook that ``after_val_epoch`` reaches
    (the checkpoint hook's best-checkpoint bookkeeping needs its file
    backend, set in its own ``before_train``) is ready. Evaluating draws no
    training randomness, so the training trajectory is unchanged; a resumed
    run (iteration > 0) does not validate again."""
    from mmengine.hooks import Hook

    class InitialVal(Hook):
        priority = 'LOWEST'

        def before_train(self, runner):
            if runner.iter == 0 and runner.val_loop is not None:
                runner.val_loop.run()

    return InitialVal()


def _train_clock_hook(max_seconds: Optional[float], path: str,
                      max_cpu_seconds: Optional[float] = None):
    """A hook that measures training time (validation excluded), stores it
    in every checkpoint (so a resumed run keeps counting), writes it to
    ``path`` and ends training after ``max_seconds`` of wall time or
    ``max_cpu_seconds`` of CPU time, whichever comes first.

    Besides wall time it sums the process's CPU time: on a machine shared
    with other jobs the wall time grows with the load, the CPU time (all
    threads) much less, so it tells what the run would take alone."""
    from mmengine.hooks import Hook

    class TrainClock(Hook):
        priority = 'VERY_HIGH'  # before CheckpointHook reads max_iters

        def __init__(self):
            self.seconds = 0.0
            self.cpu_seconds = 0.0
            self.mark = None
            self.stopped_by_time = False

        def _write(self, runner):
            with open(path, 'w') as f:
                json.dump(dict(train_seconds=self.seconds,
                               cpu_seconds=self.cpu_seconds,
                               iterations=runner.iter,
                               max_iters=runner.train_loop.max_iters,
                               stopped_by_time=self.stopped_by_time), f)

        def before_train_iter(self, runner, batch_idx, data_batch=None):
            if self.mark is None:
                self.mark = (time.perf_counter(), time.process_time())

        def after_train_iter(self, runner, batch_idx, data_batch=None,
                             outputs=None):
            now = (time.perf_counter(), time.process_time())
            self.seconds += now[0] - self.mark[0]
            self.cpu_seconds += now[1] - self.mark[1]
            self.mark = now
            loop = runner.train_loop
            spent = ((max_seconds is not None and self.seconds >= max_seconds)
                     or (max_cpu_seconds is not None
                         and self.cpu_seconds >= max_cpu_seconds))
            if spent and runner.iter + 1 < loop.max_iters:
                # This iteration becomes the last: CheckpointHook saves it
                # (save_last) and the loop validates it.
                loop._max_iters = runner.iter + 1
                self.stopped_by_time = True
                runner.logger.info(
                    f'TrainClock: {self.seconds / 60:.1f} min '
                    f'({self.cpu_seconds / 60:.1f} CPU-min) of training '
                    f'reached; stopping after iteration {runner.iter + 1}')

        def after_val_epoch(self, runner, metrics=None):
            self.mark = None  # validation time is not training time

        def before_save_checkpoint(self, runner, checkpoint):
            checkpoint['meta']['train_seconds'] = self.seconds
            checkpoint['meta']['train_cpu_seconds'] = self.cpu_seconds
            checkpoint['meta']['stopped_by_time'] = self.stopped_by_time
            self._write(runner)

        def after_load_checkpoint(self, runner, checkpoint):
            meta = checkpoint.get('meta', {})
            self.seconds = float(meta.get('train_seconds', 0.0))
            self.cpu_seconds = float(meta.get('train_cpu_seconds', 0.0))
            # Not restored: a resumed run goes on, and says it stopped by
            # time only if its own limit stops it again.

        def after_train(self, runner):
            self._write(runner)

    return TrainClock()


def _seconds(minutes: Optional[float]) -> Optional[float]:
    return None if minutes is None else 60.0 * minutes


def _labels(cfg) -> str:
    """The ground truth a config trains on, for the table's header line:
    ``'SurroundOcc'``, ``'Occ3D'`` or ``'Occ3D, no mask'`` (the loss sees
    every voxel, not only the camera-visible ones)."""
    convention = occupancy_metric(cfg, 'val')[1].get('convention')
    labels = dict(surroundocc='SurroundOcc', occ3d='Occ3D').get(
        convention, str(convention))
    if labels == 'Occ3D' and cfg.model.get('loss_mask_key') is None:
        labels += ', no mask'
    return labels


def train_one(spec: dict) -> None:
    """Train one run (in the child process); see :func:`bench_run`."""
    train_tool = load_tool('tools/train.py')
    from mmengine.registry import DATASETS, init_default_scope
    from mmengine.runner import Runner
    work_dir = spec['work_dir']
    argv = [spec['config'], '--work-dir', work_dir, '--resume']
    if spec['options']:
        argv += ['--cfg-options'] + spec['options']
    cfg = train_tool.build_cfg(train_tool.parse_args(argv))
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    loader = cfg.train_dataloader
    dataset = DATASETS.build(copy.deepcopy(loader.dataset))
    epoch_length = max(1, len(dataset) // loader.batch_size)
    max_iters = set_iteration_budget(cfg, spec['iters'],
                                     spec['val_interval'], epoch_length,
                                     spec['log_interval'])
    runner = Runner.from_cfg(cfg)
    runner.register_hook(
        _train_clock_hook(_seconds(spec['max_minutes']),
                          osp.join(work_dir, CLOCK),
                          _seconds(spec.get('max_cpu_minutes'))))
    runner.register_hook(_initial_val_hook())
    info = dict(
        labels=_labels(cfg),
        params=sum(p.numel() for p in runner.model.parameters()),
        epoch_length=epoch_length, train_samples=len(dataset),
        batch_size=loader.batch_size, max_iters=max_iters,
        device=str(next(runner.model.parameters()).device))
    with open(osp.join(work_dir, 'run_info.json'), 'w') as f:
        json.dump(info, f)
    runner.train()


# ----------------------------------------------------------------------
# The parent: runs, curves, table.
# ----------------------------------------------------------------------
def read_curves(work_dir: str) -> Dict[str, List]:
    """Training loss and validation metrics against iterations.

    Reads every ``{work_dir}/{timestamp}/vis_data/scalars.json`` (one per
    resumed segment); a later segment's record of an iteration replaces an
    earlier one.

    Returns:
        dict: ``loss`` and ``val`` lists of ``(iteration, value or
        metrics dict)``, sorted by iteration.
    """
    loss, val = {}, {}
    for path in sorted(
            glob.glob(osp.join(glob.escape(work_dir), '*', 'vis_data',
                               'scalars.json'))):
        for record in read_json_lines(path):
            step = int(record['step'])
            if 'loss' in record:
                loss[step] = float(record['loss'])
            elif 'occ/mIoU' in record:
                val[step] = {k: v for k, v in record.items()
                             if k.startswith('occ/')}
    return dict(loss=sorted(loss.items()), val=sorted(val.items()))


def plot_curves(curves: Dict[str, List], title: str, path: str) -> None:
    """Learning-curve PNG: validation IoU / mIoU (left axis, %) and
    training loss (right axis) against iterations."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4), dpi=100)
    if curves['val']:
        steps = [s for s, _ in curves['val']]
        for key, style in (('occ/mIoU', 'o-'), ('occ/IoU', 's--')):
            ax.plot(steps, [m.get(key, math.nan) for _, m in curves['val']],
                    style, label=f'val {key[4:]}')
    ax.set_xlabel('iteration')
    ax.set_ylabel('held-out IoU / mIoU (%)')
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    right = ax.twinx()
    if curves['loss']:
        right.plot([s for s, _ in curves['loss']],
                   [v for _, v in curves['loss']], color='grey', lw=1,
                   label='train loss')
        right.set_ylim(bottom=0)
    ax.set_xlim(left=0)
    right.set_ylabel('training loss')
    lines = ax.get_legend_handles_labels()
    more = right.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], loc='upper left',
              fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _load_json(path: str):
    with open(path) as f:
        return json.load(f)


def _last_checkpoint(work_dir: str) -> str:
    path = osp.join(work_dir, 'last_checkpoint')
    if not osp.isfile(path):
        raise SystemExit(f'no checkpoint in {work_dir}')
    with open(path) as f:
        return f.read().strip()


#: The settings a run extended with ``--extend`` may change.
BUDGETS = ('max_minutes', 'max_cpu_minutes')


def _budget_grows(old: dict, new: dict) -> bool:
    """Whether ``new`` is ``old`` with only larger (or no) time budgets."""
    if ({k: v for k, v in old.items() if k not in BUDGETS} !=
            {k: v for k, v in new.items() if k not in BUDGETS}):
        return False
    for key in BUDGETS:
        before, after = old.get(key), new.get(key)
        if before is None and after is not None:
            return False  # an unlimited run gets no limit afterwards
        if None not in (before, after) and after <= before:
            return False
    return True


def _keep_stopped_result(run_dir: str) -> str:
    """Move a time-stopped run's ``result.json`` aside for ``--extend``;
    its new name. A run that ended its schedule cannot be extended."""
    result = _load_json(osp.join(run_dir, RESULT))
    if not result.get('stopped_by_time'):
        raise SystemExit(
            f'{run_dir} ran its whole schedule ({result["iterations"]} '
            'iterations): --extend continues only a run that its time '
            'budget stopped; give --iters for a longer schedule in another '
            'run (--suffix).')
    kept = f'result-{result["iterations"]}it.json'
    os.replace(osp.join(run_dir, RESULT), osp.join(run_dir, kept))
    return kept


def bench_run(name: str, config: str, options: List[str], args,
              data_root: Optional[str], out: str, log_path: str) -> dict:
    """Train (or resume, or reuse) one run and evaluate it.

    A finished run is reused as it is, or with ``args.retest`` its last
    checkpoint is tested again and its row rewritten. With ``args.extend``
    a run whose settings differ only by larger time budgets continues
    (see :func:`_budget_grows`).

    Returns:
        dict: The run's row: ``name``, ``config``, ``labels``,
        ``train_s``, ``iterations``, ``metrics`` (test), ``curves``, paths.
    """
    run_dir = osp.join(out, 'runs', name)
    work_dir = osp.join(run_dir, 'train')
    if data_root is not None:
        options = data_options(data_root, config) + options
    settings = dict(config=config, options=options, iters=args.iters,
                    val_interval=args.val_interval,
                    max_minutes=args.max_minutes,
                    log_interval=args.log_interval)
    max_cpu_minutes = getattr(args, 'max_cpu_minutes', None)
    if max_cpu_minutes is not None:
        # Only when set: run folders made before the option stay reusable.
        settings['max_cpu_minutes'] = max_cpu_minutes
    extend = getattr(args, 'extend', False)
    extended = False
    for path in (osp.join(run_dir, RESULT), osp.join(run_dir, SETTINGS)):
        if osp.isfile(path):
            old = _load_json(path)
            old = old.get('settings', old)
            if old == settings:
                continue
            if not (extend and _budget_grows(old, settings)):
                raise SystemExit(
                    f'{run_dir} was made with other settings ({old} != '
                    f'{settings}); remove it or use another --suffix'
                    + ('' if not extend else ' (--extend changes only a '
                       'larger --max-minutes / --max-cpu-minutes)') + '.')
            extended = True
    finished = osp.isfile(osp.join(run_dir, RESULT))
    if finished and extended:
        kept = _keep_stopped_result(run_dir)
        print(f'\n{name}: extending the run its time budget stopped '
              f'(its result kept as {kept})')
        finished = False
    if finished and not getattr(args, 'retest', False):
        print(f'\n{name}: finished earlier, reusing {run_dir}/{RESULT}')
        return _load_json(osp.join(run_dir, RESULT))
    if not finished:
        os.makedirs(work_dir, exist_ok=True)
        with open(osp.join(run_dir, SETTINGS), 'w') as f:
            json.dump(settings, f, indent=1)
        spec = dict(settings, work_dir=work_dir)
        run(tool('tools/analysis_tools/benchmark_learning.py') +
            ['--train-one', json.dumps(spec)], log_path, f'training {name}')
    clock = _load_json(osp.join(work_dir, CLOCK))
    info = _load_json(osp.join(work_dir, 'run_info.json'))

    test_dir = osp.join(run_dir, 'test')
    cmd = tool('tools/test.py') + [
        config, _last_checkpoint(work_dir), '--work-dir', test_dir]
    # The GT voxels of every class, for the table's large-class line, and
    # the confusion matrix, for where the weak classes' voxels go.
    confusion_csv = osp.join(run_dir, CONFUSION)
    occ_metric = occupancy_metric(Config.fromfile(config), 'test')[0]
    test_options = list(options) + [
        f'{occ_metric}.class_voxel_counts=True',
        f'{occ_metric}.confusion_file={confusion_csv}'
    ]
    if args.pictures > 0:
        # Spread the pictures over the val split (its length is known from
        # the last validation's sample count only inside the Runner, so
        # take every k-th of the held-out scenes' key frames).
        num_val = args.val_scenes * args.samples
        every = max(1, num_val // args.pictures)
        cmd += ['--show-dir', osp.join(run_dir, 'pictures')]
        test_options.append(f'default_hooks.visualization.interval={every}')
    if test_options:
        cmd += ['--cfg-options'] + test_options
    run(cmd, log_path, f'testing {name}')

    curves = read_curves(work_dir)
    curve_png = osp.join(run_dir, 'curve.png')
    metrics = last_metrics(test_dir)
    plot_curves(
        curves, f'{name}: {info["labels"]}, {info["params"] / 1e6:.2f} M '
        f'params, {clock["iterations"]} it, '
        f'{clock["train_seconds"] / 60:.1f} min, '
        f'mIoU {metrics.get("occ/mIoU", math.nan):.1f}', curve_png)
    row = dict(name=name, config=config, labels=info['labels'],
               params=info['params'], device=info['device'],
               train_samples=info['train_samples'],
               epoch_length=info['epoch_length'],
               train_s=clock['train_seconds'],
               train_cpu_s=clock.get('cpu_seconds', math.nan),
               iterations=clock['iterations'],
               stopped_by_time=clock['stopped_by_time'], metrics=metrics,
               curves=curves, curve_png=curve_png,
               confusion_csv=confusion_csv,
               pictures=osp.join(run_dir, 'pictures'), settings=settings)
    with open(osp.join(run_dir, RESULT), 'w') as f:
        json.dump(row, f, indent=1)
    return row


def _best_val(row: dict) -> str:
    """Best validation mIoU of a run and the iteration it was reached."""
    val = [(m.get('occ/mIoU', math.nan), s) for s, m in row['curves']['val']]
    if not val:
        return 'n/a'
    best, step = max(val)
    return f'{pct(best)} ({step})'


def _weak_names(row: dict) -> Optional[List[str]]:
    """Classes with >= LARGE_CLASS_VOXELS GT voxels at IoU <=
    LARGE_CLASS_MIN_IOU; None when the run logged no GT voxel counts."""
    metrics = row['metrics']
    if not any(k.startswith('occ/gt_voxels/') and v is not None
               for k, v in metrics.items()):
        return None
    return [name for name in large_classes(metrics)
            if not metrics.get(f'occ/{name}', 0.0) > LARGE_CLASS_MIN_IOU]


def _weak_large_classes(row: dict) -> str:
    """:func:`_weak_names` as a table cell ('none' when every large class
    is above the line, 'n/a' without counts)."""
    weak = _weak_names(row)
    return 'n/a' if weak is None else ', '.join(weak) or 'none'


def _weak_class_confusions(row: dict) -> str:
    """For each weak large class, the two classes that take most of its
    GT voxels, e.g. ``'bicycle: empty 61 %, car 9 %'`` ('n/a' for a run
    tested before the confusion matrix was written)."""
    weak = _weak_names(row)
    if not weak:
        return 'n/a' if weak is None else 'none'
    path = row.get('confusion_csv')
    if not path or not osp.isfile(path):
        return 'n/a'
    names, confusion = read_confusion_csv(path)
    parts = []
    for name in weak:
        went = largest_confusions(confusion, names.index(name))
        parts.append(f'{name}: ' + ', '.join(
            f'{names[c]} {share * 100:.0f} %' for c, share in went))
    return '; '.join(parts)


def main(argv=None):
    """Run the benchmark (or, with ``--train-one``, one training run)."""
    args = parse_args(argv)
    if args.train_one:
        train_one(json.loads(args.train_one))
        return None
    out = osp.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    log_path = osp.join(out, 'benchmark.log')
    data_root = osp.abspath(args.data_root or osp.join(out, 'world'))
    prepare_world(data_root, log_path, args.scenes, args.samples,
                  args.image_size, args.val_scenes, args.seed)
    runs = [(name, *RUNS[name]) for name in args.runs]
    runs += [(name, config, []) for name, config in args.config]
    common = list(args.cfg_options)
    if args.train_labels:
        common += train_label_options(
            data_root, args.train_labels, log_path,
            scene_names(args.scenes - args.val_scenes + 1, args.val_scenes))
    for name, config, options in runs:
        bench_run(name + args.suffix, config, list(options) + common, args,
                  data_root, out, log_path)
    # The table holds every finished run of OUT, also those of earlier
    # invocations (other budgets or options: see each run's settings).
    rows = [_load_json(path) for path in sorted(
        glob.glob(osp.join(glob.escape(out), 'runs', '*', RESULT)))]
    table = format_table(rows, [
        ('train CPU time (all threads)',
         lambda r: f'{r.get("train_cpu_s", math.nan) / 60:.1f} min'),
        ('iterations', lambda r: str(r['iterations']) +
         (' (time limit)' if r['stopped_by_time'] else '')),
        ('epochs', lambda r: f'{r["iterations"] / r["epoch_length"]:.1f}'),
        ('params', lambda r: f'{r["params"] / 1e6:.2f} M'),
        ('best val mIoU (at it)', _best_val),
        (f'classes of >= {LARGE_CLASS_VOXELS:,} GT voxels at IoU <= '
         f'{LARGE_CLASS_MIN_IOU:g}', _weak_large_classes),
        ('their GT voxels mostly predicted as', _weak_class_confusions),
    ])
    header = (f'Held-out synthetic scenes ({args.val_scenes} of '
              f'{args.scenes}, {args.samples} key frames each, '
              f'{args.image_size[0]}x{args.image_size[1]} images); '
              f'IoU in %, a class line\'s bracket: its GT voxels.\n\n')
    with open(osp.join(out, 'results.md'), 'w') as f:
        f.write(header + table + '\n')
    with open(osp.join(out, 'results.json'), 'w') as f:
        json.dump(rows, f, indent=1)
    print('\n' + header + table)
    print(f'\nCurves: {out}/runs/*/curve.png; table: {out}/results.md')
    return rows


if __name__ == '__main__':
    main()
