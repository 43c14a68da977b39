#!/usr/bin/env python
"""Benchmark the pure-PyTorch sparse backend against spconv on CPU.

Not a test. Times the forward (eval mode, no grad) of single sparse layers
at full resolution and of the whole ``SPVCNNEncoder`` on a synthetic
nuScenes-like 10-sweep cloud (default ~300k points, 0.1 m voxels over
SDG-OCC's x, y in [-40, 40] m, z in [-1, 5.4] m), with both backends and
the same weights, and prints one table with wall time, peak memory, the
torch / spconv ratios of wall time, CPU time and memory, and the largest
output difference between the backends.

Peak memory is the growth of the process's resident set during one call,
``VmHWM - VmRSS_before`` with the heap trimmed and the mark reset first
(:class:`projects.occ_common.analysis.benchmarking.PeakMemory`, shared by the
benchmark tools): it counts every allocator (torch's, spconv's C++
buffers), which Python's ``tracemalloc`` would not.

One torch thread by default: with two, spconv 2.3.8's CPU strided conv
intermittently returns wrong features (a race inside spconv; the
``max |diff|`` column shows it), and one thread keeps the comparison fair.

Usage::

    python tools/analysis_tools/benchmark_sparse.py --quick   # ~20k \\
        points, seconds
    python tools/analysis_tools/benchmark_sparse.py           # ~300k \\
        points, minutes

The script imports the plugin's sparse package directly (unlike the train
and test tools, which get plugin code from configs), since it benchmarks
that package and no config.
"""
import argparse
import math
import statistics
import sys
import time
from typing import Callable, Dict, List, Tuple

import torch

from projects.occ_common.analysis.benchmarking import PeakMemory
from projects.occ_common.models import sparse

RANGE = (-40.0, -40.0, -1.0, 40.0, 40.0, 5.4)
VOXEL = 0.1


def synthetic_sweeps(num_points: int, sweeps: int = 10,
                     seed: int = 0) -> torch.Tensor:
    """A nuScenes-like multi-sweep cloud inside :data:`RANGE`.

    A 32-beam spinning LiDAR 1.84 m above the ground (elevations -30.7 to
    +10.7 degrees) sees the ground plane z = 0 and a random skyline of
    vertical surfaces (4-45 m away, 1-8 m tall, per 1-degree sector); the
    ego moves 0.5 m between sweeps, which smears static structure as
    accumulated sweeps do. 2 cm range noise.

    Args:
        num_points (int): Points to keep inside the range.
        sweeps (int): Number of sweeps. Defaults to 10.
        seed (int): Random seed. Defaults to 0.

    Returns:
        Tensor: Columns (x, y, z, intensity, time lag). Shape (N, 5).
    """
    gen = torch.Generator().manual_seed(seed)
    skyline_range = 4.0 + 41.0 * torch.rand(360, generator=gen)
    skyline_height = 1.0 + 7.0 * torch.rand(360, generator=gen)
    elevations = torch.deg2rad(torch.linspace(-30.67, 10.67, 32))
    per_sweep = math.ceil(num_points / sweeps)
    clouds = []
    for sweep in range(sweeps):
        kept, total = [], 0
        while total < per_sweep:
            rays = 4 * per_sweep
            azimuth = 2 * math.pi * torch.rand(rays, generator=gen)
            elevation = elevations[torch.randint(32, (rays, ), generator=gen)]
            sector = (torch.rad2deg(azimuth).long() % 360)
            wall = skyline_range[sector] / torch.cos(elevation)
            ground = torch.where(elevation < 0,
                                 1.84 / torch.sin(-elevation).clamp(min=1e-3),
                                 torch.full_like(elevation, 1e3))
            dist = torch.minimum(wall, ground)
            dist = dist + 0.02 * torch.randn(rays, generator=gen)
            xyz = torch.stack([
                dist * torch.cos(elevation) * torch.cos(azimuth) -
                0.5 * sweep, dist * torch.cos(elevation) * torch.sin(azimuth),
                1.84 + dist * torch.sin(elevation)
            ], dim=1)
            hit_wall = wall <= ground
            too_high = 1.84 + wall * torch.sin(elevation) > \
                skyline_height[sector]
            valid = ~(hit_wall & too_high)
            low = torch.tensor(RANGE[:3])
            high = torch.tensor(RANGE[3:])
            valid &= ((xyz >= low) & (xyz < high)).all(dim=1)
            xyz = xyz[valid]
            extra = torch.stack([
                torch.rand(xyz.shape[0], generator=gen),
                torch.full((xyz.shape[0], ), 0.05 * sweep)
            ], dim=1)
            kept.append(torch.cat([xyz, extra], dim=1))
            total += xyz.shape[0]
        clouds.append(torch.cat(kept)[:per_sweep])
    return torch.cat(clouds)[:num_points]


def voxelize(points: torch.Tensor, channels: int,
             seed: int = 0) -> sparse.SparseTensor:
    """Unique 0.1 m voxels of the cloud with random features.

    Returns:
        SparseTensor: One sample on the (64, 800, 800) grid. Shape (N, C).
    """
    low = torch.tensor(RANGE[:3])
    shape = tuple(round((RANGE[a + 3] - RANGE[a]) / VOXEL) for a in (2, 1, 0))
    idx = torch.floor((points[:, :3] - low) / VOXEL).long().flip(1)
    idx = torch.minimum(idx, torch.tensor(shape) - 1)
    batch = torch.zeros(idx.shape[0], dtype=torch.long)
    keys = torch.unique(sparse.linearize(batch, idx, shape))
    size_y, size_x = shape[1], shape[2]
    coords = torch.stack([
        torch.zeros_like(keys), keys // (size_y * size_x),
        keys // size_x % size_y, keys % size_x
    ], dim=1)
    gen = torch.Generator().manual_seed(seed)
    feats = torch.randn(keys.numel(), channels, generator=gen)
    return sparse.SparseTensor(feats, coords, shape, 1)


def measure(run: Callable[[], object],
            repeats: int) -> Tuple[float, float, int, object]:
    """Median wall and CPU time (s) and peak memory (bytes) of ``run``.

    One untimed warm-up call first (lazy imports, spconv's first-call
    setup); memory is taken on the first timed call. CPU time (all threads
    of the process) is far less sensitive than wall time to other jobs on
    a shared machine.
    """
    run()
    walls, cpus, peak, result = [], [], 0, None
    for i in range(repeats):
        with PeakMemory() as mem:
            cpu = time.process_time()
            start = time.perf_counter()
            result = run()
            walls.append(time.perf_counter() - start)
            cpus.append(time.process_time() - cpu)
        if i == 0:
            peak = mem.added_bytes
    return statistics.median(walls), statistics.median(cpus), peak, result


def _sorted_features(
        x: sparse.SparseTensor) -> Tuple[torch.Tensor, torch.Tensor]:
    keys = sparse.linearize(x.coords[:, 0], x.coords[:, 1:],
                            x.spatial_shape)
    order = torch.argsort(keys)
    return keys[order], x.features[order]


def _difference(a: object, b: object) -> float:
    """Largest |a - b| of two layer outputs (sites matched) or BEV maps."""
    if isinstance(a, dict):
        return (a['bev'] - b['bev']).abs().max().item()
    keys_a, feats_a = _sorted_features(a)
    keys_b, feats_b = _sorted_features(b)
    if not torch.equal(keys_a, keys_b):
        return float('inf')
    return (feats_a - feats_b).abs().max().item() if feats_a.numel() else 0.0


def layer_workloads(
        x: sparse.SparseTensor) -> Dict[str, Callable[[str], Callable]]:
    """Full-resolution layers; each maps a backend to a timed callable."""

    def make(cls, *args, **kwargs):
        torch.manual_seed(0)
        return cls(*args, **kwargs).eval()

    def subm(backend):
        layer = make(sparse.SubMConv, 32, 32, 3, backend=backend)
        return lambda: layer(x)

    def down(kernel, padding):

        def build(backend):
            layer = make(sparse.SparseConv, 32, 64, kernel, stride=2,
                         padding=padding, backend=backend)
            return lambda: layer(x)

        return build

    def inverse(backend):
        down_layer = make(sparse.SparseConv, 32, 64, 3, stride=2, padding=1,
                          indice_key='d', backend=backend)
        up = make(
            sparse.SparseInverseConv, 64, 32, 3, 'd', backend=backend)
        coarse = down_layer(x)
        return lambda: up(coarse)

    return {
        'SubMConv 3x3x3 32->32': subm,
        'SparseConv k2 s2 32->64': down(2, 0),
        'SparseConv k3 s2 p1 32->64': down(3, 1),
        'SparseInverseConv k3 64->32': inverse,
    }


def encoder_workload(points: torch.Tensor) -> Callable[[str], Callable]:
    """The default (SDG-OCC) SPVCNNEncoder on the cloud, eval mode."""

    def build(backend):
        torch.manual_seed(0)
        encoder = sparse.SPVCNNEncoder(
            in_channels=5, backend=backend).eval()
        return lambda: encoder([points])

    return build


def _format_row(cells: List[str], widths: List[int]) -> str:
    return '  '.join(c.rjust(w) if i else c.ljust(w)
                     for i, (c, w) in enumerate(zip(cells, widths)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--quick', action='store_true',
                        help='~20k points instead of ~300k')
    parser.add_argument('--points', type=int, default=None,
                        help='number of points (overrides --quick)')
    parser.add_argument('--repeats', type=int, default=3,
                        help='timed calls per measurement (median)')
    parser.add_argument('--threads', type=int, default=1,
                        help='torch CPU threads (default 1, see above)')
    parser.add_argument('--skip-encoder', action='store_true',
                        help='time single layers only')
    args = parser.parse_args()
    if not sparse.spconv_available():
        sys.exit('spconv is not installed; nothing to compare against')
    torch.set_num_threads(args.threads)
    num_points = args.points or (20_000 if args.quick else 300_000)
    points = synthetic_sweeps(num_points)
    x = voxelize(points, 32)
    print(f'points {points.shape[0]}, voxels {x.num_voxels} (0.1 m), grid '
          f'(Z, Y, X) {x.spatial_shape}, torch threads '
          f'{torch.get_num_threads()}, repeats {args.repeats}')
    workloads = layer_workloads(x)
    if not args.skip_encoder:
        workloads['SPVCNNEncoder (default)'] = encoder_workload(points)
    header = ['workload', 'out sites', 'torch ms', 'spconv ms', 'time x',
              'cpu x', 'torch MB', 'spconv MB', 'mem x', 'max |diff|']
    widths = [28, 9, 9, 9, 6, 6, 9, 9, 6, 10]
    print(_format_row(header, widths))
    with torch.no_grad():
        for name, build in workloads.items():
            stats = {}
            for backend in ('torch', 'spconv'):
                stats[backend] = measure(build(backend), args.repeats)
            (t_time, t_cpu, t_mem, t_out), (s_time, s_cpu, s_mem, s_out) = (
                stats['torch'], stats['spconv'])
            sites = (t_out['bev'].shape[-1] * t_out['bev'].shape[-2]
                     if isinstance(t_out, dict) else t_out.num_voxels)
            mem_ratio = f'{t_mem / s_mem:.2f}' if s_mem else 'n/a'
            print(_format_row([
                name, str(sites), f'{t_time * 1e3:.1f}',
                f'{s_time * 1e3:.1f}', f'{t_time / s_time:.2f}',
                f'{t_cpu / s_cpu:.2f}',
                f'{t_mem / 2**20:.1f}', f'{s_mem / 2**20:.1f}', mem_ratio,
                f'{_difference(t_out, s_out):.2e}'
            ], widths))
            sys.stdout.flush()


if __name__ == '__main__':
    main()
