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
"""
import argparse
import json
import os.path as osp
import tempfile
import time

import numpy as np
import torch

REPO = osp.dirname(
    osp.dirname(osp.dirname(osp.abspath(__file__))))


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description='Benchmark data loading')
    parser.add_argument(
        '--config',
        default=osp.join(REPO, 'configs', '_base_', 'datasets',
                         'surroundocc-nus.py'),
        help='dataset config (its train_dataloader is measured)')
    parser.add_argument(
        '--data-root',
        help='converted nuScenes root (default: generate a synthetic one)')
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
        help='samples timed per worker count (after one warm-up batch)')
    parser.add_argument(
        '--workers', type=int, nargs='+', default=[1, 2], help='workers')
    parser.add_argument(
        '--sweep-repeats',
        type=int,
        default=5,
        help='repetitions of the multi-sweep comparison')
    parser.add_argument('--out', help='write the figures to this JSON file')
    return parser.parse_args(argv)


def make_world(root, image_size):
    """Generate and convert a synthetic world with real-sized sensors."""
    from projects.occ_common.datasets.converters import nuscenes_occ_converter
    from projects.occ_common.datasets.synthetic import \
        generate_synthetic_nuscenes
    start = time.perf_counter()
    # 1024 azimuth steps x 32 beams ~ nuScenes' ~34k points per sweep.
    generate_synthetic_nuscenes(
        root,
        num_scenes=1,
        samples_per_scene=3,
        image_size=tuple(image_size),
        azimuth_bins=1024,
        write_camera_labels=False)
    nuscenes_occ_converter.create_nuscenes_occ_infos(
        root, version='v1.0-mini', val_scenes=[])
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
    """Mean seconds of every pipeline step in the main process, and the
    source image size (H, W)."""
    totals, source = {}, None
    for idx in range(num_samples):
        results = dataset.get_data_info(idx % len(dataset))
        for transform in dataset.pipeline.transforms:
            start = time.perf_counter()
            results = transform(results)
            name = type(transform).__name__
            totals[name] = totals.get(name, 0.0) + time.perf_counter() - start
            if isinstance(results, dict) and 'ori_shape' in results:
                source = list(results['ori_shape'])
    return {k: v / num_samples for k, v in totals.items()}, source


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


def main(argv=None):
    """Run the benchmark and print (and optionally save) the figures."""
    args = parse_args(argv)
    from mmengine.config import Config
    from mmengine.registry import init_default_scope
    cfg = Config.fromfile(args.config)
    init_default_scope('mmdet3d')
    from mmdet3d.registry import DATASETS

    import projects.occ_common  # noqa: F401  (as custom_imports would)
    report = dict(config=args.config)
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
