"""What ``make demo`` runs: synthetic world -> two trained models -> table.

``make demo`` runs this after setting up the environment. It

1. generates the synthetic nuScenes-format world (unless it exists),
2. converts it with ``tools/create_data.py`` (through nuscenes-devkit),
3. for the small OccCylindrical and the small SDG-Fusion config (``MODELS``):
   evaluates the untrained model, trains it with ``tools/train.py`` for the
   demo's epochs and evaluates the trained checkpoint with
   ``tools/test.py --show-dir`` (pictures of prediction against ground
   truth),
4. prints one table (model, IoU, mIoU, per-class IoU, train time) and writes
   it with the pictures to ``--out``.

Every step is a subprocess of the user-facing tools, so the demo shows
mmengine's own logs and progress bars; this script imports no plugin code.
"""
import argparse
import json
import os
import os.path as osp
import shutil
import time
from typing import List

from projects.occ_common.analysis.tool_runs import (LARGE_CLASS_VOXELS,
                                                    data_options, format_table,
                                                    large_classes,
                                                    last_metrics, pct,
                                                    prepare_world, run,
                                                    stretched_times, tool)

#: (name, config, label convention, epochs). The small configs of the
#: learning benchmark, trained in the demo for the epochs given here on
#: the 24 training samples of the demo world (4 scenes x 6 key
#: frames; the fifth scene is the held-out val split), which fit the demo's
#: 20-minute budget on 2 idle CPU cores: 384 iterations of OccCylindrical
#: and 240 of SDG-Fusion (about 1.45 and 1.6 s each), each a warm-up and a
#: cosine decay to 0, stretched from the config's own schedule. With the
#: 12 training samples of a 3-scene world, 144 iterations of
#: OccCylindrical (its config's 12 epochs) left four large classes of the
#: val scene under 5 IoU (construction vehicle 1.0, pedestrian 2.5,
#: trailer 1.0, truck 0.0; 2026-11-26, 27454a3). The tiny configs are
#: smoke-sized for the tests.
MODELS = [
    ('OccCylindrical', 'configs/occ_cyl/'
     'occcyl_small_1xb1-12e_surroundocc-nus-synthetic.py', 'SurroundOcc',
     16),
    ('SDG-Fusion', 'configs/sdg_occ/'
     'sdgocc-fusion_small_1xb1-20e_occ3d-nus-synthetic.py', 'Occ3D', 10),
]


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', default='demo_out', help='output folder')
    parser.add_argument(
        '--data-root',
        default='data/nuscenes_synthetic',
        help='where the synthetic world is (or is generated)')
    parser.add_argument('--scenes', type=int, default=5)
    parser.add_argument('--samples', type=int, default=6)
    parser.add_argument(
        '--epochs',
        type=int,
        default=None,
        help='train every model this many epochs (default: the demo\'s '
        'own, in MODELS); the LR warm-up and decay are stretched to fit')
    parser.add_argument(
        '--models',
        nargs='+',
        default=[m[0] for m in MODELS],
        choices=[m[0] for m in MODELS])
    parser.add_argument(
        '--baseline',
        nargs='+',
        metavar='CONFIG WORK_DIR [CFG_OPTIONS]',
        help=argparse.SUPPRESS)  # internal: evaluate an untrained model
    return parser.parse_args(argv)


def evaluate_untrained(config: str, work_dir: str, *options: str) -> None:
    """Test the freshly initialised model of ``config`` (no checkpoint).

    Runs in its own process (``demo/synthetic_demo.py --baseline ...``) so
    that its Runner and logger do not mix with the demo's steps.
    """
    from mmengine.config import Config, DictAction
    from mmengine.runner import Runner
    cfg = Config.fromfile(config)
    overrides = argparse.ArgumentParser()
    overrides.add_argument('opts', nargs='*', action=DictAction)
    cfg.merge_from_dict(overrides.parse_args(list(options)).opts or {})
    cfg.work_dir = work_dir
    cfg.load_from = None
    Runner.from_cfg(cfg).test()


def schedule_options(config: str, epochs: int) -> List[str]:
    """The ``--cfg-options`` that train ``config`` for ``epochs``.

    Args:
        config (str): Config path.
        epochs (int): Epochs to train.

    Returns:
        list[str]: Overrides that set the epochs, validate and checkpoint
        once at the end, and stretch every LR
        scheduler's times (warm-up, decay) by epochs / the config's epochs
        as the learning benchmark does, so that a shorter run still warms
        up and decays, and a longer one does not train its last epochs at
        the decayed rate.
    """
    from mmengine.config import Config
    cfg = Config.fromfile(config, import_custom_modules=False)
    own = cfg.train_cfg.max_epochs
    options = [
        f'train_cfg.max_epochs={epochs}', f'train_cfg.val_interval={epochs}',
        f'default_hooks.checkpoint.interval={epochs}'
    ]
    for i, scheduler in enumerate(cfg.get('param_scheduler') or []):
        for key, value in stretched_times(scheduler, epochs / own).items():
            value = str(value).replace(' ', '')  # one shell word a list
            options.append(f'param_scheduler.{i}.{key}={value}')
    return options


def selected_models(args: argparse.Namespace) -> list:
    """The ``MODELS`` entries that ``--models`` names, in ``MODELS``
    order, each with the epochs to train: ``--epochs`` where given, else
    the demo's own."""
    return [(name, config, labels, args.epochs or epochs)
            for name, config, labels, epochs in MODELS
            if name in args.models]


#: A class of the validation split with at least LARGE_CLASS_VOXELS GT
#: voxels has been learned when training gained this many IoU points.
MIN_GAIN = 5.0
#: Evaluations log the GT voxels of every class (the table's brackets).
COUNTS = 'test_evaluator.class_voxel_counts=True'


def unlearned_large_classes(row: dict) -> str:
    """Large classes (see :func:`large_classes`) whose IoU rose by less
    than MIN_GAIN points over the untrained model's ('none' if all rose)."""
    trained, untrained = row['metrics'], row['untrained']
    slow = [
        name for name in large_classes(trained)
        if not trained.get(f'occ/{name}', 0.0) >=
        untrained.get(f'occ/{name}', 0.0) + MIN_GAIN
    ]
    return ', '.join(slow) or 'none'


def main(argv=None):
    """Run the demo."""
    args = parse_args(argv)
    if args.baseline:
        evaluate_untrained(*args.baseline)
        return
    start = time.time()
    out = osp.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    log_path = osp.join(out, 'demo.log')
    open(log_path, 'w').close()
    data_root = args.data_root

    prepare_world(data_root, log_path, args.scenes, args.samples)

    rows = []
    for name, config, labels, epochs in selected_models(args):
        schedule = schedule_options(config, epochs)
        slug = name.lower().replace('-', '_')
        work = osp.join(out, 'work_dirs', slug)
        shutil.rmtree(work, ignore_errors=True)
        data = data_options(data_root)

        run(tool('demo/synthetic_demo.py') +
            ['--baseline', config, osp.join(work, 'untrained')] + data +
            [COUNTS], log_path)
        untrained = last_metrics(osp.join(work, 'untrained'))

        tic = time.time()
        run(tool('tools/train.py') + [
            config, '--work-dir',
            osp.join(work, 'train'), '--cfg-options'
        ] + schedule + data, log_path)
        train_s = time.time() - tic

        pictures = osp.join(out, 'pictures', slug)
        run(tool('tools/test.py') + [
            config,
            osp.join(work, 'train', f'epoch_{epochs}.pth'), '--work-dir',
            osp.join(work, 'test'), '--show-dir', pictures,
            '--cfg-options'
        ] + data + [COUNTS], log_path)
        rows.append(
            dict(
                name=name,
                config=config,
                labels=labels,
                epochs=epochs,
                train_s=train_s,
                metrics=last_metrics(osp.join(work, 'test')),
                untrained=untrained,
                pictures=pictures))

    table = format_table(
        rows, [('epochs', lambda r: str(r['epochs'])),
               ('mIoU untrained',
                lambda r: pct(r['untrained'].get('occ/mIoU'))),
               (f'classes of >= {LARGE_CLASS_VOXELS:,} GT voxels that gained '
                f'< {MIN_GAIN:g} IoU points', unlearned_large_classes)])
    with open(osp.join(out, 'results.md'), 'w') as f:
        f.write(table + '\n')
    with open(osp.join(out, 'results.json'), 'w') as f:
        json.dump(rows, f, indent=2)
    print('\n' + '=' * 78)
    print('Demo results on the synthetic validation split (IoU %):\n')
    print(table)
    print(f'\nPictures of prediction against ground truth: {out}/pictures/')
    print(f'Table: {out}/results.md, log: {log_path}; '
          f'total {(time.time() - start) / 60:.1f} min')


if __name__ == '__main__':
    main()
