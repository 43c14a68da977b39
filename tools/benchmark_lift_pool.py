"""Benchmark OccCylindrical's lift-pool and whole-model latency on CPU.

Measures, at the size a config describes (the paper's by default: 6 views of
1600x900 padded to 1600x928, 50 depth bins, a 58x100 feature map, i.e.
6 x 50 x 58 x 100 = 1.74 M pseudo points):

1. the peak memory of the camera lift + per-voxel max pool
   (``lift_max_pool`` with the config's cylinder grid and chunk size) with
   the fused autograd Function and with the naive outer-product-then-pool
   path, forward and forward + backward, on the voxel indices of the real
   frustum geometry. Each measurement runs in a fresh child process: the
   peak RSS minus the RSS once the inputs exist
   (:class:`projects.occ_common.utils.benchmarking.PeakMemory`) is the
   memory the lift itself needs;
2. the forward latency of the whole model (``--model``), optionally at a
   reduced image size (``--img-scale``) when the full one does not fit the
   machine.

The model is built through the config's ``custom_imports``; the lift
measurement also calls the plugin's frustum helpers to make its inputs.

Example::

    python tools/benchmark_lift_pool.py \
        configs/occ_cyl/occcyl_r50-swint_3xb1-24e_surroundocc-nus.py --model
"""
import argparse
import json
import math
import os
import subprocess
import sys
import time

import numpy as np
import torch
from mmengine.config import Config
from mmengine.registry import init_default_scope
from mmengine.utils import import_modules_from_strings

from projects.occ_common.utils.benchmarking import PeakMemory


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('config', help='OccCylindrical config')
    parser.add_argument(
        '--img-scale',
        type=float,
        default=1.0,
        help='scale of the image size for the whole-model latency')
    parser.add_argument(
        '--model', action='store_true', help='also time the whole model')
    parser.add_argument(
        '--skip-lift', action='store_true', help='skip the lift-pool part')
    parser.add_argument(
        '--repeat', type=int, default=2, help='timed model forwards')
    parser.add_argument(
        '--num-points', type=int, default=250000,
        help='LiDAR points (10 nuScenes sweeps hold ~250k-350k)')
    parser.add_argument('--threads', type=int, default=2)
    parser.add_argument('--child', help=argparse.SUPPRESS)
    return parser.parse_args()


def _build_cfg(config):
    cfg = Config.fromfile(config)
    import_modules_from_strings(**cfg.get('custom_imports', {}))
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    return cfg


def _paper_geometry(cfg, img_scale=1.0):
    """nuScenes-like 6-camera ring at the config's image size."""
    from mmdet3d.structures import Det3DDataSample
    img_h, img_w = (int(round(s * img_scale)) for s in cfg.img_size)
    div = cfg.model.data_preprocessor.pad_size_divisor
    pad_h, pad_w = (math.ceil(s / div) * div for s in (img_h, img_w))
    num_cams = len(cfg.cam_names)
    focal = 1266.0 * img_w / 1600.0
    cam2img = np.tile(np.eye(4, dtype=np.float32), (num_cams, 1, 1))
    cam2img[:, 0, 0] = cam2img[:, 1, 1] = focal
    cam2img[:, 0, 2], cam2img[:, 1, 2] = img_w / 2, img_h / 2
    lidar2cam = np.zeros((num_cams, 4, 4), np.float32)
    for k, yaw in enumerate(np.deg2rad([0, -55, 55, 180, 110, -110])):
        rot = np.array([[np.sin(yaw), -np.cos(yaw), 0], [0, 0, -1],
                        [np.cos(yaw), np.sin(yaw), 0]])
        lidar2cam[k, :3, :3] = rot
        lidar2cam[k, :3, 3] = -rot @ np.array([1.0, 0.0, 1.5])
        lidar2cam[k, 3, 3] = 1
    aug = np.tile(np.eye(4, dtype=np.float32), (num_cams, 1, 1))
    meta = dict(
        sample_idx=0,
        img_shape=(img_h, img_w),
        cam2img=cam2img,
        lidar2cam=lidar2cam,
        img_aug_matrix=aug,
        lidar2img=aug @ cam2img @ lidar2cam)
    return Det3DDataSample(metainfo=meta), (pad_h, pad_w)


def measure_lift(config, mode, threads):
    """Child: peak memory and time of lift_max_pool in one mode."""
    torch.set_num_threads(threads)
    cfg = _build_cfg(config)
    from mmdet3d.registry import MODELS

    # The lift's inputs need the plugin's cylinder and geometry helpers and
    # the lift itself; the config's custom_imports has already imported
    # them.
    from projects.occ_common.models.layers import (cartesian_to_cylindrical,
                                                   create_frustum,
                                                   frustum_to_lidar)
    from projects.occ_cyl.cylindrical import CylinderGrid
    from projects.occ_cyl.lift_pool import lift_max_pool
    model_cfg = cfg.model
    # The cylinder OccCylindrical builds for its occupancy range.
    cylinder = CylinderGrid.covering(model_cfg.point_cloud_range,
                                     model_cfg.cylinder_shape)
    fusion = MODELS.build(
        dict(model_cfg.tpv_fusion, fused_lift=mode.startswith('fused'),
             with_lidar=False, cylinder=cylinder))
    sample, (pad_h, pad_w) = _paper_geometry(cfg)
    stride = model_cfg.img_encoder.out_stride
    feat_h, feat_w = pad_h // stride, pad_w // stride
    context_channels = model_cfg.depth_net.context_channels
    frustum = create_frustum((pad_h, pad_w), (feat_h, feat_w),
                             model_cfg.depth_bound)
    l2i = torch.as_tensor(sample.metainfo['lidar2img'])[None]
    cam_points = frustum_to_lidar(frustum, l2i)
    voxel_idx = cylinder.flat_index(cartesian_to_cylindrical(cam_points))[0]
    del cam_points
    num_bins = frustum.shape[0]
    gen = torch.Generator().manual_seed(0)
    num_imgs = l2i.shape[1]
    depth = torch.randn(num_imgs, num_bins, feat_h, feat_w,
                        generator=gen).softmax(1)
    context = torch.randn(num_imgs, context_channels, feat_h, feat_w,
                          generator=gen)
    backward = mode.endswith('backward')
    depth.requires_grad_(backward)
    context.requires_grad_(backward)
    with PeakMemory() as memory:
        start = time.perf_counter()
        vol = lift_max_pool(
            depth,
            context,
            voxel_idx,
            cylinder.num_voxels,
            fused=fusion.fused_lift,
            chunk_size=fusion.lift_chunk_size)
        if backward:
            vol.backward(torch.ones_like(vol))
        seconds = time.perf_counter() - start
    points = depth.numel()
    return dict(
        mode=mode,
        points=points,
        channels=context_channels,
        voxels=cylinder.num_voxels,
        occupied_voxels=int((vol.detach().abs().sum(1) > 0).sum()),
        chunk_size=fusion.lift_chunk_size,
        peak_extra_mib=memory.added_bytes / 2**20,
        naive_feature_tensor_mib=points * context_channels * 4 / 2**20,
        output_mib=vol.numel() * 4 / 2**20,
        seconds=seconds,
        peak_reset=memory.hwm_reset)


def measure_model(config, img_scale, repeat, num_points, threads):
    """Child: forward latency and peak memory of the whole model."""
    torch.set_num_threads(threads)
    cfg = _build_cfg(config)
    from mmdet3d.registry import MODELS
    model = MODELS.build(cfg.model).eval()
    sample, (pad_h, pad_w) = _paper_geometry(cfg, img_scale)
    gen = torch.Generator().manual_seed(0)
    imgs = torch.randn(1, len(cfg.cam_names), 3, pad_h, pad_w, generator=gen)
    # 10 sweeps: uniform in the 100 m box, ground-heavy heights.
    xyz = (torch.rand(num_points, 3, generator=gen) - 0.5) * torch.tensor(
        [100.0, 100.0, 8.0]) + torch.tensor([0.0, 0.0, -1.0])
    points = [torch.cat([xyz, torch.rand(num_points, 2, generator=gen)], 1)]
    inputs = dict(imgs=imgs, points=points)
    times = []
    with PeakMemory() as memory, torch.no_grad():
        for i in range(repeat + 1):
            start = time.perf_counter()
            model._forward(inputs, [sample])
            times.append(time.perf_counter() - start)
    params = sum(p.numel() for p in model.parameters())
    return dict(
        mode='model',
        image=(pad_h, pad_w),
        num_points=num_points,
        params_m=params / 1e6,
        first_forward_s=times[0],
        forward_s=float(np.median(times[1:])) if repeat else times[0],
        peak_extra_mib=memory.added_bytes / 2**20,
        threads=threads)


def _child(args, mode):
    cmd = [sys.executable, __file__, args.config, '--child', mode,
           '--threads', str(args.threads), '--img-scale', str(args.img_scale),
           '--repeat', str(args.repeat), '--num-points', str(args.num_points)]
    env = dict(os.environ, OMP_NUM_THREADS=str(args.threads))
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f'{mode} failed:\n{proc.stderr[-3000:]}')
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main():
    args = parse_args()
    if args.child:
        if args.child == 'model':
            out = measure_model(args.config, args.img_scale, args.repeat,
                                args.num_points, args.threads)
        else:
            out = measure_lift(args.config, args.child, args.threads)
        print(json.dumps(out))
        return
    if not args.skip_lift:
        report_lift(args)
    if args.model:
        r = _child(args, 'model')
        print(f'whole model: image {r["image"]}, {r["num_points"]} points, '
              f'{r["params_m"]:.2f} M parameters, forward '
              f'{r["forward_s"]:.1f} s (first {r["first_forward_s"]:.1f} s) '
              f'on {r["threads"]} threads, peak +{r["peak_extra_mib"]:.0f} '
              'MiB')


def report_lift(args):
    """Run the four lift-pool children and print the comparison."""
    results = [
        _child(args, mode) for mode in ('naive', 'fused', 'naive-backward',
                                        'fused-backward')
    ]
    print(f'{"lift-pool":16s} {"points":>9s} {"C":>4s} {"voxels":>8s} '
          f'{"peak MiB":>9s} {"time s":>7s}')
    for r in results:
        print(f'{r["mode"]:16s} {r["points"]:9d} {r["channels"]:4d} '
              f'{r["voxels"]:8d} {r["peak_extra_mib"]:9.1f} '
              f'{r["seconds"]:7.2f}')
    r0 = results[0]
    print(f'naive (points x C) feature tensor alone: '
          f'{r0["naive_feature_tensor_mib"]:.1f} MiB; pooled volume: '
          f'{r0["output_mib"]:.1f} MiB; occupied voxels: '
          f'{r0["occupied_voxels"]}')
    for fwd, name in ((0, 'forward'), (2, 'forward+backward')):
        ratio = results[fwd + 1]['peak_extra_mib'] / max(
            results[fwd]['peak_extra_mib'], 1e-9)
        print(f'fused / naive peak memory ({name}): {ratio:.3f}')


if __name__ == '__main__':
    main()
