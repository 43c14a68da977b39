"""Steps shared by ``demo/synthetic_demo.py`` and
``tools/analysis_tools/benchmark_learning.py``.

They live here, not in ``tools/``, because the tools import their helpers
as installed packages (never from ``tools/`` on ``sys.path``).

Both drive the user-facing tools (``create_synthetic_nuscenes.py``,
``create_data.py``, ``train.py``, ``test.py``) as subprocesses, read the
metrics mmengine logged, and print a results table. Like the tools, this
module imports no plugin code.
"""
import glob
import importlib.util
import json
import os.path as osp
import subprocess
import sys
from types import ModuleType
from typing import Dict, List, Optional, Sequence

from mmengine import Config

#: The repository root (projects/occ_common/analysis/ -> three levels up).
REPO_ROOT = osp.dirname(
    osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__)))))
#: The generator writes this file first and marks it complete at the end.
WORLD_META = osp.join('synthetic_gt', 'meta.json')
INFO_PREFIX = 'nuscenes_occ'


#: Scheduler arguments that are positions or lengths in time.
SCHEDULE_TIME_KEYS = ('begin', 'end', 'T_max', 'milestones', 'step_size',
                      'total_steps')


def stretched_times(scheduler: dict, factor: float) -> dict:
    """The time arguments of an LR scheduler config times ``factor``.

    Args:
        scheduler (dict): One ``param_scheduler`` entry.
        factor (float): E.g. new length / planned length, times the
            iterations of an epoch to rewrite an epoch-based one in
            iterations.

    Returns:
        dict: Each of ``SCHEDULE_TIME_KEYS`` the scheduler has, scaled and
        rounded to whole units (a list such as ``milestones`` element by
        element). A positive time stays at least 1 and ``end`` stays after
        ``begin``: a 50-iteration warm-up squeezed into a short run keeps
        one iteration instead of becoming a scheduler mmengine refuses
        (``end <= begin``).
    """

    def scaled(value):
        if isinstance(value, (list, tuple)):
            return [scaled(v) for v in value]
        return max(int(round(value * factor)), 1 if value > 0 else 0)

    out = {
        key: scaled(scheduler[key])
        for key in SCHEDULE_TIME_KEYS if key in scheduler
    }
    if 'end' in out and out['end'] <= out.get('begin', 0):
        out['end'] = out.get('begin', 0) + 1
    return out


def load_tool(script: str) -> ModuleType:
    """A tool script imported as a module (its ``main`` not run).

    The tools are scripts in several folders, not a package; one that
    reuses another's functions (``benchmark_learning.py`` trains through
    ``tools/train.py``'s) loads it by path.

    Args:
        script (str): Path relative to the repository root, e.g.
            ``'tools/train.py'``.

    Returns:
        ModuleType: The module, named ``tool_<stem>``.
    """
    name = 'tool_' + osp.splitext(osp.basename(script))[0]
    spec = importlib.util.spec_from_file_location(name,
                                                  osp.join(REPO_ROOT, script))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def tool(name: str) -> List[str]:
    """The command prefix of a tool script with this interpreter.

    Args:
        name (str): Path relative to the repository root, e.g.
            ``'tools/train.py'``.
    """
    return [sys.executable, osp.join(REPO_ROOT, name)]


def run(cmd: List[str], log_path: str, what: str = 'step') -> None:
    """Run ``cmd`` from the repository root, echo and log its output.

    Raises:
        SystemExit: If the command fails; names the command and the log.
    """
    print(f'\n$ {" ".join(cmd)}', flush=True)
    with open(log_path, 'a') as log:
        proc = subprocess.Popen(
            cmd,
            cwd=REPO_ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1)
        for line in proc.stdout:
            sys.stdout.write(line)
            log.write(line)
        if proc.wait() != 0:
            raise SystemExit(f'{what} failed ({proc.returncode}): '
                             f'{" ".join(cmd)}; see {log_path}')


def scene_names(first: int, count: int) -> List[str]:
    """Synthetic scene names ``scene-XXXX`` (1-based, as generated)."""
    return [f'scene-{i:04d}' for i in range(first, first + count)]


def prepare_world(data_root: str,
                  log_path: str,
                  scenes: int,
                  samples: int,
                  image_size: Optional[Sequence[int]] = None,
                  val_scenes: Optional[int] = None,
                  seed: int = 0) -> None:
    """Generate (unless present) and convert a synthetic world.

    The world is reused when ``data_root`` already holds a complete one
    with the same scene count, samples, image size and seed; one written
    with other parameters is refused rather than silently mixed in.

    Args:
        data_root (str): Dataset root.
        log_path (str): Log file of the tools' output.
        scenes (int): Number of scenes.
        samples (int): Key frames per scene.
        image_size (Sequence[int], optional): Camera ``(W, H)``. Defaults
            to the generator's.
        val_scenes (int, optional): The last ``val_scenes`` scenes form the
            held-out val split. Defaults to the converter's rule (the last
            fifth).
        seed (int): Generator seed. Defaults to 0.

    Raises:
        SystemExit: If ``data_root`` holds a different or unfinished world.
    """
    meta_path = osp.join(data_root, WORLD_META)
    if osp.isfile(meta_path):
        with open(meta_path) as f:
            meta = json.load(f)
        params = meta.get('parameters', {})
        wanted = dict(num_scenes=scenes, samples_per_scene=samples, seed=seed)
        if image_size is not None:
            wanted['image_size'] = list(image_size)
        differ = {k: (params.get(k), v) for k, v in wanted.items()
                  if params.get(k) != v}
        if differ or not meta.get('complete'):
            raise SystemExit(
                f'{data_root} holds another synthetic world (have, want: '
                f'{differ}, complete: {meta.get("complete")}); remove it or '
                'choose another --data-root.')
    else:
        cmd = tool('tools/dataset_converters/create_synthetic_nuscenes.py') + [
            data_root, '--scenes', str(scenes), '--samples', str(samples),
            '--seed', str(seed)]
        if image_size is not None:
            cmd += ['--image-size'] + [str(v) for v in image_size]
        run(cmd, log_path, 'world generation')
    if not osp.isfile(
            osp.join(data_root, f'{INFO_PREFIX}_infos_val.pkl')):
        cmd = tool('tools/create_data.py') + [
            'nuscenes', '--root-path', data_root, '--version', 'v1.0-mini']
        if val_scenes is not None:
            if not 0 < val_scenes < scenes:
                raise SystemExit(f'expected 0 < val scenes < {scenes}, got '
                                 f'{val_scenes}')
            cmd += ['--val-scenes'] + scene_names(scenes - val_scenes + 1,
                                                  val_scenes)
        run(cmd, log_path, 'conversion')


def evaluator_keys(cfg, split: str) -> List[tuple]:
    """``(option key, evaluator config)`` of every evaluator of a split.

    Args:
        cfg (mmengine.Config): A loaded config.
        split (str): ``'val'`` or ``'test'``.

    Returns:
        list[tuple]: ``('test_evaluator', cfg)`` for a single evaluator,
        ``('test_evaluator.i', cfg_i)`` for each of a list.
    """
    evaluators = cfg[f'{split}_evaluator']
    if isinstance(evaluators, dict):
        return [(f'{split}_evaluator', evaluators)]
    return [(f'{split}_evaluator.{i}', evaluator)
            for i, evaluator in enumerate(evaluators)]


def occupancy_metric(cfg, split: str) -> tuple:
    """``(option key, config)`` of a split's one ``OccupancyMetric``.

    Raises:
        SystemExit: When the split has none or several.
    """
    found = [(key, evaluator) for key, evaluator in evaluator_keys(cfg, split)
             if evaluator.get('type') == 'OccupancyMetric']
    if len(found) != 1:
        raise SystemExit(f'{cfg.filename}: expected one OccupancyMetric in '
                         f'{split}_evaluator, found {len(found)}')
    return found[0]


def data_options(data_root: str, config: Optional[str] = None) -> List[str]:
    """``--cfg-options`` pointing every dataloader at ``data_root``.

    Args:
        data_root (str): The dataset folder.
        config (str, optional): With a config file, also the evaluators
            that read an info file themselves (RayIoU's origins).
    """
    root = data_root.rstrip('/') + '/'
    options = [
        f'{split}_dataloader.dataset.data_root={root}'
        for split in ('train', 'val', 'test')
    ]
    if config is not None:
        cfg = Config.fromfile(config)
        options += [
            f'{key}.data_root={root}' for split in ('val', 'test')
            for key, evaluator in evaluator_keys(cfg, split)
            if 'data_root' in evaluator
        ]
    return options


def read_json_lines(path: str) -> List[dict]:
    """The records of an mmengine json log (one JSON object a line)."""
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def last_metrics(work_dir: str) -> Dict[str, float]:
    """The metrics of the newest test run logged under ``work_dir``.

    mmengine's LoggerHook writes ``{work_dir}/{timestamp}/{timestamp}.json``.

    Raises:
        SystemExit: If no log or no ``occ/mIoU`` record is found.
    """
    logs = sorted(glob.glob(osp.join(glob.escape(work_dir), '*', '*.json')))
    if not logs:
        raise SystemExit(f'no metrics logged in {work_dir}')
    metrics = [r for r in read_json_lines(logs[-1]) if 'occ/mIoU' in r]
    if not metrics:
        raise SystemExit(f'{logs[-1]} holds no occ/mIoU')
    return metrics[-1]


def class_keys(rows: Sequence[dict]) -> List[str]:
    """Per-class metric names (``occ/<class>``) of the rows, in order
    (RayIoU's own keys are not classes: the table gives them a line)."""
    classes = []
    for r in rows:
        for key in r['metrics']:
            name = key[len('occ/'):]
            if (key.startswith('occ/') and '/' not in name
                    and name not in ('IoU', 'mIoU')
                    and not name.startswith('RayIoU')
                    and name not in classes):
                classes.append(name)
    return classes


#: Key prefix of OccupancyMetric's GT voxel counts (class_voxel_counts).
GT_VOXELS = 'occ/gt_voxels/'
#: The learning benchmark's bar: a class with at least this many GT voxels
#: in the held-out split should score above LARGE_CLASS_MIN_IOU.
LARGE_CLASS_VOXELS = 1000
LARGE_CLASS_MIN_IOU = 10.0


def large_classes(metrics: Dict[str, float],
                  min_voxels: int = LARGE_CLASS_VOXELS) -> List[str]:
    """Classes with at least ``min_voxels`` GT voxels in ``metrics``
    (none when the metric logged no counts; a count of None, as results
    logged before the counts were floats hold, is no count), without the
    empty class of either convention (SurroundOcc's ``empty``, Occ3D's
    ``free``): that one is the ``IoU`` line's business."""
    return [
        key[len(GT_VOXELS):] for key, count in metrics.items()
        if key.startswith(GT_VOXELS) and count is not None
        and count >= min_voxels
        and key[len(GT_VOXELS):] not in ('empty', 'free')
    ]


def class_cell(metrics: Dict[str, float], name: str) -> str:
    """IoU of class ``name``, with its GT voxel count when logged."""
    cell = pct(metrics.get(f'occ/{name}'))
    count = metrics.get(GT_VOXELS + name)
    return cell if count is None else f'{cell} ({int(count):,})'


def pct(value) -> str:
    """A percentage with two decimals, ``n/a`` for None / NaN."""
    return 'n/a' if value is None or value != value else f'{value:.2f}'


def ray_iou_cell(metrics: Dict[str, float]) -> str:
    """``'RayIoU (@1 / @2 / @4)'`` of a row, ``n/a`` without RayIoU."""
    if 'occ/RayIoU' not in metrics:
        return 'n/a'
    return (pct(metrics['occ/RayIoU']) + ' (' + ' / '.join(
        pct(metrics.get(f'occ/RayIoU@{tau}')) for tau in (1, 2, 4)) + ')')


def format_table(rows: List[dict], extra: Sequence[tuple] = ()) -> str:
    """Markdown table: one column per row (model), one line per metric.

    Args:
        rows (list[dict]): Each with ``name``, ``labels``, ``train_s``,
            ``metrics`` (logged ``occ/*`` keys).
        extra (Sequence[tuple]): ``(label, fn)`` lines after the mIoU;
            ``fn(row)`` gives the cell text.

    Returns:
        str: The table.
    """
    names = [r['name'] for r in rows]
    lines = ['| | ' + ' | '.join(names) + ' |',
             '|---' * (len(names) + 1) + '|']

    def add(label, values):
        lines.append(f'| {label} | ' + ' | '.join(values) + ' |')

    add('labels', [r['labels'] for r in rows])
    add('train time', [f'{r["train_s"] / 60:.1f} min' for r in rows])
    add('IoU', [pct(r['metrics'].get('occ/IoU')) for r in rows])
    add('**mIoU**', [pct(r['metrics'].get('occ/mIoU')) for r in rows])
    if any('occ/RayIoU' in r['metrics'] for r in rows):
        add('RayIoU (@1 / @2 / @4 m)', [ray_iou_cell(r['metrics'])
                                        for r in rows])
    for label, fn in extra:
        add(label, [fn(r) for r in rows])
    for name in class_keys(rows):
        add(name, [class_cell(r['metrics'], name) for r in rows])
    return '\n'.join(lines)
