#!/usr/bin/env python
"""Benchmark RayIoU's per-sample cost on one CPU thread.

Not a test. Times what ``OccRayIoUMetric.process`` does for one sample:
cast all rays of T origins (39 x 360 each, 8 origins by default, as
SparseOcc's protocol gives most samples) through a prediction and its
ground truth together and count them; and, as with ``cache_gt_rays``, the
prediction alone against cached GT hits. Prints the median wall and CPU
time per sample (CPU time is far less sensitive to other jobs on a shared
machine) over every sample and round; the target is <= 0.5 s. With
``--keep-freed-memory`` glibc keeps freed memory (as ``CPUMallocTuningHook``
does), which spares the page faults of the traversal's temporaries.

The grids are Occ3D-sized (200 x 200 x 16, 0.4 m) street scenes drawn
here: a road, sidewalks and terrain on the ground layer, cars and
pedestrians, buildings and trees along the street, free space beyond. The
prediction is the GT with the errors of a fair model: objects moved by a
voxel, 10 % of the occupied voxels relabelled, 0.5 % false positives. With
``--labels`` real Occ3D ``labels.npz`` files serve as GT instead. The
origins are 8 LiDAR positions 1.84 m above the road, 10 m apart.

Usage::

    OMP_NUM_THREADS=1 python tools/analysis_tools/benchmark_ray_iou.py
    python tools/analysis_tools/benchmark_ray_iou.py --samples 3 \\
        --labels data/nuscenes/gts/scene-0003/*/labels.npz
"""
import argparse
import json
import statistics
from typing import List, Tuple

import numpy as np
import torch

from projects.occ_common.analysis.benchmarking import timed_runs
from projects.occ_common.datasets.nuscenes_classes import OCC3D_CLASS_NAMES
from projects.occ_common.evaluation import cast_rays, count_ray_hits
from projects.occ_common.utils.glibc_malloc import (MMAP_THRESHOLD,
                                                    TRIM_THRESHOLD,
                                                    tune_glibc_malloc)

FREE = OCC3D_CLASS_NAMES.index('free')
SHAPE = (200, 200, 16)
LABEL = {name: i for i, name in enumerate(OCC3D_CLASS_NAMES)}


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--samples', type=int, default=5,
                        help='samples (drawn scenes or --labels files)')
    parser.add_argument('--origins', type=int, default=8,
                        help='ray origins per sample (SparseOcc: <= 8)')
    parser.add_argument('--rounds', type=int, default=3,
                        help='timed calls per sample')
    parser.add_argument('--labels', nargs='+',
                        help='Occ3D labels.npz files to use as GT')
    parser.add_argument('--seed', type=int, default=0, help='random seed')
    parser.add_argument(
        '--keep-freed-memory',
        action='store_true',
        help='glibc keeps freed memory for reuse instead of returning it to '
        'the kernel and faulting it in again (what CPUMallocTuningHook does '
        'for CPU runs; projects/occ_common/utils/glibc_malloc.py)')
    parser.add_argument('--out', help='write the results as JSON here')
    return parser.parse_args(argv)


def _box(grid, rng, label, size, x_range, y_range, z0):
    """Fill a box of ``size`` voxels at a random place with ``label``."""
    x = rng.integers(*x_range)
    y = rng.integers(*y_range)
    grid[x:x + size[0], y:y + size[1], z0:z0 + size[2]] = label


def street_gt(rng: np.random.Generator) -> np.ndarray:
    """An Occ3D-like street scene along x. Shape (200, 200, 16)."""
    gt = np.full(SHAPE, FREE, dtype=np.uint8)
    # The ground is voxel layer 2 (z in [-0.2, 0.2] m).
    gt[:, :, 2] = LABEL['terrain']
    gt[:, 80:120, 2] = LABEL['driveable_surface']
    gt[:, 70:80, 2] = gt[:, 120:130, 2] = LABEL['sidewalk']
    for _ in range(rng.integers(10, 25)):
        _box(gt, rng, LABEL['car'], (11, 5, 4), (0, 190), (82, 114), 3)
    for _ in range(rng.integers(5, 15)):
        _box(gt, rng, LABEL['pedestrian'], (1, 1, 4), (0, 200), (70, 130), 3)
    for side in ((40, 66), (134, 160)):
        for _ in range(rng.integers(6, 12)):
            height = int(rng.integers(6, 14))
            label = LABEL['manmade'] if rng.random() < 0.6 else \
                LABEL['vegetation']
            _box(gt, rng, label, (rng.integers(8, 30), 10, height),
                 (0, 190), side, 3)
    return gt


def noisy_prediction(gt: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``gt`` with a fair model's errors (see the module docstring)."""
    pred = np.roll(gt, tuple(rng.integers(-1, 2, 3)), (0, 1, 2))
    pred[:, :, :3] = gt[:, :, :3]
    occupied = pred != FREE
    flip = occupied & (rng.random(SHAPE) < 0.1)
    pred[flip] = rng.integers(0, FREE, int(flip.sum()))
    spurious = ~occupied & (rng.random(SHAPE) < 0.005)
    pred[spurious] = rng.integers(0, FREE, int(spurious.sum()))
    return pred


def origins(count: int) -> np.ndarray:
    """LiDAR positions along the road, 10 m apart. Shape (T, 3)."""
    x = (np.arange(count) - (count - 1) / 2) * 10.0
    return np.stack([x, np.full(count, 0.3), np.full(count, 1.84)], 1)


def samples(args) -> List[Tuple[np.ndarray, np.ndarray]]:
    """(pred, gt) pairs of the benchmark."""
    rng = np.random.default_rng(args.seed)
    if args.labels:
        gts = [
            np.load(path)['semantics'].astype(np.uint8)
            for path in args.labels[:args.samples]
        ]
    else:
        gts = [street_gt(rng) for _ in range(args.samples)]
    return [(noisy_prediction(gt, rng), gt) for gt in gts]


def main(argv=None) -> dict:
    """Time every sample and print the medians."""
    args = parse_args(argv)
    torch.set_num_threads(1)
    malloc = 'default malloc'
    if args.keep_freed_memory:
        kept = tune_glibc_malloc(MMAP_THRESHOLD, TRIM_THRESHOLD)
        malloc = ('malloc keeps freed memory'
                  if kept else 'malloc unchanged (not glibc)')
    where = origins(args.origins)
    times = {'pred + GT': dict(wall_s=[], cpu_s=[]),
             'pred, GT cached': dict(wall_s=[], cpu_s=[])}
    rays = 0
    for pred, gt in samples(args):
        pred_hits, gt_hits = cast_rays([pred, gt], where)
        rays += int((gt_hits.label != FREE).sum())
        calls = {
            'pred + GT':
            lambda: count_ray_hits(*cast_rays([pred, gt], where)),
            'pred, GT cached':
            lambda: count_ray_hits(
                cast_rays([pred], where, only=gt_hits.label != FREE)[0],
                gt_hits),
        }
        for name, call in calls.items():
            one = timed_runs(call, args.rounds)
            for key in ('wall_s', 'cpu_s'):
                times[name][key] += one[key]
    result = {
        name: {key: statistics.median(t[key])
               for key in ('wall_s', 'cpu_s')}
        for name, t in times.items()
    }
    print(f'RayIoU per sample, 1 thread, {args.origins} origins x '
          f'{39 * 360} rays, {len(times["pred + GT"]["wall_s"])} timed '
          f'calls, {malloc}; {rays / max(args.samples, 1):.0f} GT rays hit '
          'per sample):')
    print(f'{"cast + count":18s}{"wall (s)":>10s}{"CPU (s)":>10s}')
    for name, value in result.items():
        print(f'{name:18s}{value["wall_s"]:10.3f}{value["cpu_s"]:10.3f}')
    if args.out:
        with open(args.out, 'w') as f:
            json.dump(dict(result, malloc=malloc, args=vars(args)), f,
                      indent=2)
    return result


if __name__ == '__main__':
    main()
