"""Benchmark the occupancy data pipeline at the paper resolution.

Measures, in one run:

1. samples / s through the full training pipeline of a dataset config
   (multi-view 1600x900 images, 10 LiDAR sweeps, occupancy GT, depth and
   semantic maps, packing) with 1 and 2 dataloader workers;
2. the time of each pipeline step in the main process;
3. our ``LoadOccPointsFromMultiSweeps`` against mmdet3d 1.4's
   ``LoadPointsFromMultiSweeps`` on the same sample (time, and how far
   mmdet3d's sweep points land from ours: open-mmlab/mmdetection3d#3054).

Without ``--data-root`` a small synthetic world with 1600x900 images is
generated into a temporary folder and converted first::

    python tools/analysis_tools/benchmark_data.py                       # \\
        synthetic world
    python tools/analysis_tools/benchmark_data.py --data-root data/nuscenes \\
        --config configs/_base_/datasets/occ3d-nus.py    # real nuScenes

``--real-sample [DIR]`` instead times the training pipeline of one or more
full configs on the real nuScenes key frame beside the checkout
(``../shared/data/nuscenes_real_sample``), in this process with one torch
thread: per-sample wall and process CPU seconds and each step's share,
the configs taking turns in ``--rounds`` rounds of ``--num-samples``
samples. The sample has no sweeps, lidarseg or occupancy labels: the data
root built from it supplies stand-ins (:data:`STAND_INS`), and a config of
several key frames (``num_frames`` > 1) is skipped, as the sample has no
previous key frame::

    python tools/analysis_tools/benchmark_data.py --real-sample \\
        --config configs/sdg_occ/sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py
"""
import argparse
import contextlib
import json
import os
import os.path as osp
import pickle
import random
import tempfile
import time

import numpy as np
import torch

from projects.occ_common.analysis.benchmarking import summarise

REPO = osp.dirname(
    osp.dirname(osp.dirname(osp.abspath(__file__))))
#: nuScenes sweeps a key frame has (mmdet3d's ``--max-sweeps``), and the
#: LiDAR's period (20 Hz) that spaces the stand-in sweeps in time.
NUM_SWEEPS, SWEEP_PERIOD = 10, 0.05
#: The raw lidarseg class of every stand-in point label (-> class 11).
STAND_IN_LIDARSEG = 'flat.driveable_surface'
#: What ``--real-sample`` supplies that the sample lacks, and which way
#: each biases the figures.
STAND_INS = (
    f'sweeps: the key frame itself as each of the {NUM_SWEEPS} sweeps '
    f'(identity sensor2lidar, {SWEEP_PERIOD} s apart): the real point '
    'count, but read from the page cache, so sweep loading is a lower bound',
    'occupancy labels: an all-empty grid of the config\'s format '
    '(SurroundOcc: no occupied rows; Occ3D: all free, masks set), cheaper '
    'to read than a real label, so LoadOccupancyGT is a lower bound',
    f'lidarseg: one label ({STAND_IN_LIDARSEG}) per key-frame point, the '
    'real count with no noise points dropped: about the real cost',
    'all files on a local disk, read again and again (page cache): the '
    'totals are a lower bound for a cold dataset on a slow disk',
)


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description='Benchmark data loading')
    parser.add_argument(
        '--config',
        nargs='+',
        default=[
            osp.join(REPO, 'configs', '_base_', 'datasets',
                     'surroundocc-nus.py')
        ],
        help='dataset or full config (its train_dataloader is measured); '
        'several with --real-sample')
    parser.add_argument(
        '--data-root',
        help='converted nuScenes root (default: generate a synthetic one)')
    parser.add_argument(
        '--real-sample',
        nargs='?',
        const='',
        metavar='DIR',
        help='time the configs\' train pipelines on the real nuScenes key '
        'frame in DIR (default: ../shared/data/nuscenes_real_sample) with '
        'stand-ins for its missing sweeps and labels, in this process')
    parser.add_argument(
        '--rounds',
        type=int,
        default=3,
        help='--real-sample: rounds in which the configs take turns')
    parser.add_argument(
        '--info-prefix', default='nuscenes_occ', help='info file prefix')
    parser.add_argument(
        '--image-size',
        type=int,
        nargs=2,
        default=(1600, 900),
        help='synthetic world image width height')
    parser.add_argument(
        '--num-samples',
        type=int,
        default=12,
        help='samples timed per worker count (after one warm-up batch); '
        'with --real-sample per config and round (after one warm-up)')
    parser.add_argument(
        '--workers', type=int, nargs='+', default=[1, 2], help='workers')
    parser.add_argument(
        '--sweep-repeats',
        type=int,
        default=5,
        help='repetitions of the multi-sweep comparison')
    parser.add_argument('--out', help='write the figures to this JSON file')
    args = parser.parse_args(argv)
    if args.num_samples < 1 or args.rounds < 1:
        parser.error('--num-samples and --rounds must be at least 1')
    if args.real_sample is None and len(args.config) > 1:
        parser.error('several --config only with --real-sample')
    if args.real_sample is not None and args.data_root is not None:
        parser.error('--real-sample builds its own data root: no --data-root')
    return args


def make_world(root, image_size):
    """Generate and convert a synthetic world with real-sized sensors."""
    from projects.occ_common.datasets.converters import nuscenes_occ_converter
    from projects.occ_common.synthetic import generate_synthetic_nuscenes
    start = time.perf_counter()
    # 1024 azimuth steps x 32 beams ~ nuScenes' ~34k points per sweep.
    generate_synthetic_nuscenes(
        root,
        num_scenes=1,
        samples_per_scene=3,
        image_size=tuple(image_size),
        azimuth_bins=1024,
        write_camera_labels=False)
    # The converter refuses an empty val split; the one scene is both
    # (only the train split is timed).
    nuscenes_occ_converter.create_nuscenes_occ_infos(
        root, version='v1.0-mini')
    return time.perf_counter() - start


def loader_throughput(cfg, num_workers, num_samples):
    """Samples / s of the train dataloader after one warm-up batch."""
    from mmengine.runner import Runner
    loader_cfg = cfg.train_dataloader.copy()
    loader_cfg.update(
        num_workers=num_workers,
        persistent_workers=False,
        batch_size=1,
        sampler=dict(type='InfiniteSampler', shuffle=True))
    loader = Runner.build_dataloader(loader_cfg, seed=0)
    batches = iter(loader)
    next(batches)  # worker start-up and first sample
    start = time.perf_counter()
    for _ in range(num_samples):
        next(batches)
    return num_samples / (time.perf_counter() - start)


def step_times(dataset, num_samples):
    """Mean wall seconds of every pipeline step in the main process (from
    :func:`time_samples`), and the source image size (H, W)."""
    runs, results = time_samples(dataset, num_samples)
    means = {
        name: float(np.mean([run['steps'][name][0] for run in runs]))
        for name in runs[0]['steps'] if name != 'get_data_info'
    }
    return means, list(results['data_samples'].metainfo['ori_shape'])


def compare_sweeps(dataset, repeats):
    """Our sweep merge vs mmdet3d's on sample 0: times and disagreement."""
    from mmdet3d.datasets.transforms import LoadPointsFromMultiSweeps
    from mmdet3d.registry import TRANSFORMS
    load = TRANSFORMS.build(
        dict(type='LoadOccPointsFromFile', coord_type='LIDAR', load_dim=5,
             use_dim=5))
    ours = TRANSFORMS.build(
        dict(type='LoadOccPointsFromMultiSweeps', sweeps_num=10,
             test_mode=True))
    theirs = LoadPointsFromMultiSweeps(
        sweeps_num=10, use_dim=[0, 1, 2, 3, 4], test_mode=True)
    info = dataset.get_data_info(0)
    out, times = {}, dict(ours=[], mmdet3d=[])
    for _ in range(repeats):
        for name, merge in (('ours', ours), ('mmdet3d', theirs)):
            results = load(dict(info))
            start = time.perf_counter()
            out[name] = merge(results)['points'].tensor.numpy()
            times[name].append(time.perf_counter() - start)
    gap = np.linalg.norm(out['ours'][:, :3] - out['mmdet3d'][:, :3], axis=1)
    return dict(
        points=len(out['ours']),
        ours_ms=1e3 * float(np.median(times['ours'])),
        mmdet3d_ms=1e3 * float(np.median(times['mmdet3d'])),
        max_gap_m=float(gap.max()),
        mean_gap_m=float(gap.mean()))


def make_real_root(sample_dir, root):
    """A data root of the real key frame with :data:`STAND_INS`.

    Links the sample's files into ``root``, adds the stand-ins to a copy
    of its mmdet3d info file, and extends that with the library's
    converter, as ``tools/create_data.py --from-mmdet3d-info`` does.

    Args:
        sample_dir (str): The real sample's folder.
        root (str): An empty folder.

    Returns:
        str: The written info file.
    """
    from projects.occ_common.analysis.real_sample import INFO_FILE
    from projects.occ_common.datasets.converters import extend_mmdet3d_infos
    from projects.occ_common.datasets.nuscenes_classes import \
        LIDARSEG_RAW_CLASS_NAMES
    from projects.occ_common.datasets.occ_formats import OCC_FORMATS
    from projects.occ_common.fileio.safe_names import safe_file_name
    from projects.occ_common.fileio.safe_pickle import load_info_file
    infos = load_info_file(osp.join(sample_dir, INFO_FILE))
    for name in os.listdir(sample_dir):
        if name != INFO_FILE and not name.endswith('.md'):
            os.symlink(osp.join(sample_dir, name), osp.join(root, name))
    entry = infos['data_list'][0]
    token = safe_file_name(entry['token'], 'sample token', INFO_FILE)
    lidar = entry['lidar_points']
    key_file = osp.join(sample_dir, osp.basename(lidar['lidar_path']))
    num_points = osp.getsize(key_file) // (4 * lidar['num_pts_feats'])
    entry['lidar_sweeps'] = [
        dict(
            lidar_points=dict(
                lidar_path=lidar['lidar_path'],
                lidar2ego=np.asarray(lidar['lidar2ego']).tolist(),
                sensor2lidar=np.eye(4).tolist()),
            ego2global=np.asarray(entry['ego2global']).tolist(),
            timestamp=entry['timestamp'] - SWEEP_PERIOD * (k + 1))
        for k in range(NUM_SWEEPS)
    ]
    seg = f'{token}_lidarseg.bin'
    np.full(num_points, LIDARSEG_RAW_CLASS_NAMES.index(STAND_IN_LIDARSEG),
            np.uint8).tofile(osp.join(root, seg))
    entry['pts_semantic_mask_path'] = seg
    # Where the converter looks for each format's label of this sample.
    surroundocc = osp.join(root, 'nuscenes_occ', 'samples',
                           osp.basename(lidar['lidar_path']) + '.npy')
    os.makedirs(osp.dirname(surroundocc))
    np.save(surroundocc, np.zeros((0, 4), np.int64))
    occ3d = osp.join(root, 'gts', 'real_sample', token,
                     'labels.npz')
    os.makedirs(osp.dirname(occ3d))
    spec = OCC_FORMATS['occ3d']
    np.savez_compressed(
        occ3d,
        semantics=np.full(spec.grid_size, spec.empty_label, np.uint8),
        mask_lidar=np.ones(spec.grid_size, bool),
        mask_camera=np.ones(spec.grid_size, bool))
    infos['data_list'] = [entry]
    mmdet3d_info = osp.join(root, 'nuscenes_infos_real.pkl')
    with open(mmdet3d_info, 'wb') as f:
        pickle.dump(infos, f)
    return extend_mmdet3d_infos.extend_mmdet3d_info_file(mmdet3d_info,
                                                         root)[1]


def time_samples(dataset, num_samples):
    """Wall and process CPU seconds of the pipeline, step by step, over
    samples 0, 1, ... (cycling).

    Args:
        dataset (BaseDataset): The dataset.
        num_samples (int): Runs of the pipeline.

    Returns:
        tuple[list[dict], dict]: Per run ``wall``, ``cpu`` and ``steps``
        (step name -> ``(wall, cpu)``; ``get_data_info`` is the info's
        copy), and the last run's output.
    """
    runs, results = [], None
    for index in range(num_samples):
        steps = {}
        start = last = (time.perf_counter(), time.process_time())
        results = dataset.get_data_info(index % len(dataset))
        for transform in [None] + list(dataset.pipeline.transforms):
            if transform is not None:
                results = transform(results)
            now = (time.perf_counter(), time.process_time())
            name = 'get_data_info' if transform is None \
                else type(transform).__name__
            wall, cpu = steps.get(name, (0.0, 0.0))
            steps[name] = (wall + now[0] - last[0], cpu + now[1] - last[1])
            last = now
        runs.append(
            dict(wall=last[0] - start[0], cpu=last[1] - start[1],
                 steps=steps))
    return runs, results


@contextlib.contextmanager
def one_core():
    """Run the pipeline as one loader worker on one core, then restore.

    torch single-threaded (as in a worker), OpenCV's own threads off (as
    mmengine's Runner sets them), and numpy's BLAS and OpenMP pools at one
    thread (threadpoolctl, when installed), so that a large matmul does
    not borrow a second core and the wall time is one core's.

    Yields:
        dict: ``torch_threads`` and ``native_threads`` (the BLAS / OpenMP
        pools' limit, or how they were left).
    """
    import cv2
    before = torch.get_num_threads(), cv2.getNumThreads()
    torch.set_num_threads(1)
    cv2.setNumThreads(0)
    try:
        from threadpoolctl import threadpool_limits
        limits, native = threadpool_limits(1), 1
    except ImportError:
        limits, native = None, 'as loaded (no threadpoolctl)'
    try:
        yield dict(torch_threads=1, native_threads=native)
    finally:
        if limits is not None:
            limits.restore_original_limits()
        torch.set_num_threads(before[0])
        cv2.setNumThreads(before[1])


def real_sample_report(args):
    """Time each config's train pipeline on the real sample.

    The configs take turns in ``args.rounds`` rounds (alternating their
    order) of ``args.num_samples`` samples each, after one warm-up sample
    each, so that load on a shared machine spreads over all of them.

    Args:
        args (argparse.Namespace): From :func:`parse_args`.

    Returns:
        dict: ``sample_dir``, ``stand_ins``, ``torch_threads``,
        ``native_threads`` (numpy's BLAS / OpenMP pools) and per
        config (``configs``) either ``skipped`` (a reason) or ``samples``,
        ``wall_s`` / ``cpu_s`` (:func:`summary` of the per-sample
        seconds), ``round_median_wall_s``, ``steps`` (mean wall and CPU
        seconds per step, slowest first), ``img_input`` and ``points``.
        Only ``skipped`` when the sample is absent.
    """
    from projects.occ_common.analysis.real_sample import (INFO_FILE,
                                                          REAL_SAMPLE_DIR)
    sample_dir = args.real_sample or REAL_SAMPLE_DIR
    report = dict(sample_dir=sample_dir)
    if not osp.isfile(osp.join(sample_dir, INFO_FILE)):
        report['skipped'] = (f'no real nuScenes sample: {INFO_FILE} is not '
                             f'in {sample_dir}')
        return report
    from mmdet3d.registry import DATASETS
    from mmengine.config import Config
    from mmengine.registry import init_default_scope

    import projects.occ_common  # noqa: F401  (as custom_imports would)

    np.random.seed(0)
    random.seed(0)
    init_default_scope('mmdet3d')
    report.update(stand_ins=list(STAND_INS), rounds=args.rounds, configs={})
    with one_core() as threads, tempfile.TemporaryDirectory(
            prefix='occ_bench_real_') as root:
        report.update(threads)
        info_file = make_real_root(sample_dir, root)
        datasets = {}
        for path in args.config:
            cfg = Config.fromfile(path)
            for module in cfg.get('custom_imports', {}).get('imports', []):
                __import__(module)
            dataset_cfg = cfg.train_dataloader.dataset
            if dataset_cfg.get('num_frames', 1) > 1:
                report['configs'][path] = dict(skipped=(
                    f'num_frames={dataset_cfg.num_frames}: the real sample '
                    'has no previous key frame'))
                continue
            dataset_cfg.update(data_root=root, ann_file=info_file,
                               data_prefix=dict())
            datasets[path] = DATASETS.build(dataset_cfg)
            _, out = time_samples(datasets[path], 1)  # warm-up
            report['configs'][path] = dict(
                img_input=list(out['inputs']['img'].shape),
                points=int(out['inputs']['points'].shape[0]))
        runs = {path: [] for path in datasets}
        order = list(datasets)
        for round_ in range(args.rounds):
            for path in order if round_ % 2 == 0 else order[::-1]:
                runs[path].append(
                    time_samples(datasets[path], args.num_samples)[0])
    for path, rounds in runs.items():
        flat = [run for round_ in rounds for run in round_]
        steps = {}
        for name in flat[0]['steps']:
            walls, cpus = zip(*(run['steps'][name] for run in flat))
            steps[name] = dict(wall_s=float(np.mean(walls)),
                               cpu_s=float(np.mean(cpus)))
        report['configs'][path].update(
            samples=len(flat),
            wall_s=summarise([run['wall'] for run in flat]),
            cpu_s=summarise([run['cpu'] for run in flat]),
            round_median_wall_s=[
                float(np.median([run['wall'] for run in round_]))
                for round_ in rounds
            ],
            steps=dict(
                sorted(steps.items(), key=lambda kv: -kv[1]['wall_s'])))
    return report


def print_real_sample_report(report):
    """The per-config table and each config's three slowest steps."""
    if 'skipped' in report:
        print(f'skipped: {report["skipped"]}')
        return
    print('stand-ins:\n' + ''.join(f'  - {s}\n' for s in report['stand_ins']))
    print(f'threads: torch {report["torch_threads"]}, BLAS / OpenMP '
          f'{report["native_threads"]}; {report["rounds"]} rounds')
    print('config | samples | wall s median (min-max) | '
          'CPU s median (min-max)')
    for path, entry in report['configs'].items():
        name = osp.splitext(osp.basename(path))[0]
        if 'skipped' in entry:
            print(f'{name} | skipped: {entry["skipped"]}')
            continue
        wall, cpu = entry['wall_s'], entry['cpu_s']
        slowest = ', '.join(f'{k} {1e3 * v["wall_s"]:.0f} ms'
                            for k, v in list(entry['steps'].items())[:3])
        print(f'{name} | {entry["samples"]} | {wall["median"]:.3f} '
              f'({wall["min"]:.3f}-{wall["max"]:.3f}) | '
              f'{cpu["median"]:.3f} ({cpu["min"]:.3f}-{cpu["max"]:.3f})'
              f'\n    slowest steps (mean wall): {slowest}')


def main(argv=None):
    """Run the benchmark and print (and optionally save) the figures."""
    args = parse_args(argv)
    if args.real_sample is not None:
        report = real_sample_report(args)
        print_real_sample_report(report)
        if args.out:
            with open(args.out, 'w') as f:
                json.dump(report, f, indent=1)
        return report
    from mmengine.config import Config
    from mmengine.registry import init_default_scope
    cfg = Config.fromfile(args.config[0])
    init_default_scope('mmdet3d')
    from mmdet3d.registry import DATASETS

    import projects.occ_common  # noqa: F401  (as custom_imports would)
    report = dict(config=args.config[0])
    tmp = None
    root = args.data_root
    if root is None:
        tmp = tempfile.TemporaryDirectory(prefix='occ_bench_')
        root = tmp.name
        report['world_seconds'] = make_world(root, args.image_size)
    dataset_cfg = cfg.train_dataloader.dataset
    dataset_cfg.update(
        data_root=root, ann_file=f'{args.info_prefix}_infos_train.pkl')
    dataset = DATASETS.build(dataset_cfg)
    sample = dataset[0]
    report['img_input'] = list(sample['inputs']['img'].shape)
    report['points'] = int(sample['inputs']['points'].shape[0])
    # Dataloader workers run torch single-threaded; so do the step timings.
    torch.set_num_threads(1)
    report['step_seconds'], report['source_image'] = step_times(dataset, 3)
    report['multi_sweep'] = compare_sweeps(dataset, args.sweep_repeats)
    report['samples_per_second'] = {
        str(w): loader_throughput(cfg, w, args.num_samples)
        for w in args.workers
    }
    print(json.dumps(report, indent=1))
    if args.out:
        with open(args.out, 'w') as f:
            json.dump(report, f, indent=1)
    if tmp is not None:
        tmp.cleanup()
    return report


if __name__ == '__main__':
    main()
