"""Benchmark OccCylindrical's lift-pool: Table VI counts, memory, latency.

Measures, at the size a config describes (the paper's by default: 6 views of
1600x900 padded to 1600x928, 50 depth bins, a 58x100 feature map, i.e.
6 x 50 x 58 x 100 = 1.74 M pseudo points):

1. ``--table6``: the pseudo points before and the occupied cylinder voxels
   after the per-voxel max pool, lifted with the real calibration of the
   nuScenes key frame in ``../shared/data/nuscenes_real_sample`` through the
   config's cylinder and depth bins, for the paper config and its Table VI
   ablations (d = 2, 10 m), next to the paper's counts;
2. the peak memory of the camera lift + per-voxel max pool
   (``lift_max_pool`` into the occupied voxels of the config's cylinder,
   with its chunk size) with the fused autograd Function and with the
   naive outer-product-then-pool path, forward and forward + backward, on
   the voxel indices of the real calibration (a synthetic six-camera ring
   where the sample is absent). Each measurement runs in a fresh child
   process: the peak RSS minus the RSS once the inputs exist
   (:class:`projects.occ_common.analysis.benchmarking.PeakMemory`) is the
   memory the lift itself needs;
3. ``--model``: the forward latency and peak memory of the whole model,
   optionally at a reduced image size (``--img-scale``) when the full one
   does not fit the machine.

The model is built through the config's ``custom_imports``; the lift
measurement also calls the plugin's frustum helpers to make its inputs.

Example::

    python tools/analysis_tools/benchmark_lift_pool.py \
        configs/occ_cyl/occcyl_r50-swins_3xb1-24e_surroundocc-nus.py \
        --table6 --model
"""
import argparse
import json
import math
import os
import os.path as osp
import subprocess
import sys
import time

import numpy as np
import torch
from mmengine.config import Config
from mmengine.registry import init_default_scope
from mmengine.utils import import_modules_from_strings

from projects.occ_common.analysis.benchmarking import PeakMemory
from projects.occ_common.analysis.real_sample import (MISSING_REASON,
                                                      real_cameras,
                                                      real_lidar2img,
                                                      real_sample_dir)

#: Table VI of the paper: depth interval d (m) -> pseudo points before /
#: after the per-voxel max pool, and the GPU memory.
TABLE6 = {
    1.0: (1_740_000, 552_178, '10.63 GB'),
    2.0: (870_000, 279_359, '6.77 GB'),
    10.0: (174_000, 57_612, '5.50 GB'),
}
#: The Table VI ablations of a paper config, relative to its folder.
TABLE6_ABLATIONS = ('ablations/occcyl-d2m_{}', 'ablations/occcyl-d10m_{}')


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('config', help='OccCylindrical config')
    parser.add_argument(
        '--table6', action='store_true',
        help='print the Table VI counts of the config and its d = 2, 10 m '
        'ablations on the real calibration')
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


def _cylinder(cfg):
    """The cylinder OccCylindrical builds for the config."""
    from projects.occ_cyl.cylindrical import CylinderGrid
    return CylinderGrid.for_box(cfg.model.point_cloud_range,
                                **cfg.model.cylinder)


def _ring_lidar2img(num_cams, img_h, img_w):
    """nuScenes-like six-camera ring at the given image size."""
    focal = 1266.0 * img_w / 1600.0
    cam2img = np.tile(np.eye(4), (num_cams, 1, 1))
    cam2img[:, 0, 0] = cam2img[:, 1, 1] = focal
    cam2img[:, 0, 2], cam2img[:, 1, 2] = img_w / 2, img_h / 2
    lidar2cam = np.zeros((num_cams, 4, 4))
    for k, yaw in enumerate(np.deg2rad([0, -55, 55, 180, 110, -110])):
        rot = np.array([[np.sin(yaw), -np.cos(yaw), 0], [0, 0, -1],
                        [np.cos(yaw), np.sin(yaw), 0]])
        lidar2cam[k, :3, :3] = rot
        lidar2cam[k, :3, 3] = -rot @ np.array([1.0, 0.0, 1.5])
        lidar2cam[k, 3, 3] = 1
    return cam2img, lidar2cam


def _geometry(cfg, img_scale=1.0):
    """One sample's camera metainfo and the padded input size.

    The real calibration of the shared nuScenes frame when it is there and
    the images are full-size (1600 x 900), else a synthetic ring.
    """
    from mmdet3d.structures import Det3DDataSample
    img_h, img_w = (int(round(s * img_scale)) for s in cfg.img_size)
    div = cfg.model.data_preprocessor.pad_size_divisor
    pad_h, pad_w = (math.ceil(s / div) * div for s in (img_h, img_w))
    num_cams = len(cfg.cam_names)
    cam2img, lidar2cam = _ring_lidar2img(num_cams, img_h, img_w)
    source = 'synthetic six-camera ring'
    if real_sample_dir() and (img_h, img_w) == (900, 1600):
        cam2img, lidar2cam = (m.numpy() for m in real_cameras())
        source = 'real nuScenes calibration'
    aug = np.tile(np.eye(4), (num_cams, 1, 1))
    meta = dict(
        sample_idx=0,
        img_shape=(img_h, img_w),
        cam2img=cam2img.astype(np.float32),
        lidar2cam=lidar2cam.astype(np.float32),
        img_aug_matrix=aug.astype(np.float32),
        lidar2img=(aug @ cam2img @ lidar2cam).astype(np.float32))
    return Det3DDataSample(metainfo=meta), (pad_h, pad_w), source


def table6(config):
    """Table VI counts of a paper config and its d = 2, 10 m ablations.

    Returns:
        list[dict]: Per config: ``d``, ``points``, ``voxels``, the paper's
        ``paper_voxels`` and the ``error_pct``.
    """
    from projects.occ_cyl.cylindrical import pseudo_point_voxels
    if not real_sample_dir():
        raise FileNotFoundError(f'--table6: {MISSING_REASON}')
    folder, name = osp.split(osp.abspath(config))
    configs = [config] + [
        osp.join(folder, pattern.format(name.split('_', 1)[1]))
        for pattern in TABLE6_ABLATIONS
    ]
    lidar2img = real_lidar2img()
    rows = []
    for path in configs:
        cfg = _build_cfg(path)
        pad_h, pad_w = (math.ceil(s / cfg.model.data_preprocessor
                                  .pad_size_divisor) *
                        cfg.model.data_preprocessor.pad_size_divisor
                        for s in cfg.img_size)
        stride = cfg.model.img_encoder.out_stride
        points, voxels = pseudo_point_voxels(
            _cylinder(cfg), lidar2img, (pad_h, pad_w),
            (pad_h // stride, pad_w // stride), cfg.model.depth_bound)
        step = float(cfg.model.depth_bound[2])
        paper_points, paper_voxels, _ = TABLE6[step]
        rows.append(
            dict(config=osp.relpath(path), d=step, points=points,
                 voxels=voxels, paper_points=paper_points,
                 paper_voxels=paper_voxels,
                 error_pct=100.0 * (voxels / paper_voxels - 1)))
    return rows


def measure_lift(config, mode, threads):
    """Child: peak memory and time of lift_max_pool in one mode."""
    torch.set_num_threads(threads)
    cfg = _build_cfg(config)

    # The lift's inputs need the plugin's cylinder and geometry helpers and
    # the lift itself; the config's custom_imports has already imported
    # them.
    from projects.occ_common.models.layers import (cartesian_to_cylindrical,
                                                   create_frustum,
                                                   frustum_to_lidar)
    from projects.occ_cyl.lift_pool import lift_max_pool
    model_cfg = cfg.model
    cylinder = _cylinder(cfg)
    fusion_cfg = model_cfg.tpv_fusion
    chunk_size = fusion_cfg.get('lift_chunk_size', 16384)
    sample, (pad_h, pad_w), source = _geometry(cfg)
    stride = model_cfg.img_encoder.out_stride
    feat_h, feat_w = pad_h // stride, pad_w // stride
    context_channels = model_cfg.depth_net.context_channels
    frustum = create_frustum((pad_h, pad_w), (feat_h, feat_w),
                             model_cfg.depth_bound)
    l2i = torch.as_tensor(sample.metainfo['lidar2img'])[None]
    cam_points = frustum_to_lidar(frustum, l2i)
    # As TPVPolarFusion: pool into the occupied voxels only.
    voxels, rows = cylinder.occupied(
        cylinder.flat_index(cartesian_to_cylindrical(cam_points)))
    rows = rows[0]
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
        pooled = lift_max_pool(
            depth,
            context,
            rows,
            voxels.numel(),
            fused=mode.startswith('fused'),
            chunk_size=chunk_size)
        if backward:
            pooled.backward(torch.ones_like(pooled))
        seconds = time.perf_counter() - start
    points = depth.numel()
    return dict(
        mode=mode,
        geometry=source,
        points=points,
        channels=context_channels,
        voxels=cylinder.num_voxels,
        occupied_voxels=voxels.numel(),
        chunk_size=chunk_size,
        peak_extra_mib=memory.added_bytes / 2**20,
        naive_feature_tensor_mib=points * context_channels * 4 / 2**20,
        output_mib=pooled.numel() * 4 / 2**20,
        dense_volume_mib=cylinder.num_voxels * context_channels * 4 / 2**20,
        seconds=seconds,
        peak_reset=memory.hwm_reset)


def measure_model(config, img_scale, repeat, num_points, threads):
    """Child: forward latency and peak memory of the whole model."""
    torch.set_num_threads(threads)
    cfg = _build_cfg(config)
    from mmdet3d.registry import MODELS
    model = MODELS.build(cfg.model).eval()
    sample, (pad_h, pad_w), source = _geometry(cfg, img_scale)
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
        geometry=source,
        image=(pad_h, pad_w),
        num_points=num_points,
        params_m=params / 1e6,
        first_forward_s=times[0],
        forward_s=float(np.median(times[1:])) if repeat else times[0],
        peak_extra_mib=memory.added_bytes / 2**20,
        peak_kind=memory.kind,
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


def report_table6(config):
    """Print the Table VI comparison."""
    print('Table VI on the real calibration (pseudo points before / '
          'occupied voxels after the per-voxel max pool):')
    print(f'{"d (m)":>6s} {"points":>9s} {"voxels":>8s} {"paper":>8s} '
          f'{"error":>7s}  config')
    for r in table6(config):
        print(f'{r["d"]:6.0f} {r["points"]:9d} {r["voxels"]:8d} '
              f'{r["paper_voxels"]:8d} {r["error_pct"]:+6.1f}%  '
              f'{r["config"]}')


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
    if args.table6:
        report_table6(args.config)
    if not args.skip_lift:
        report_lift(args)
    if args.model:
        r = _child(args, 'model')
        print(f'whole model ({r["geometry"]}): image {r["image"]}, '
              f'{r["num_points"]} points, {r["params_m"]:.2f} M parameters, '
              f'forward {r["forward_s"]:.1f} s (first '
              f'{r["first_forward_s"]:.1f} s) on {r["threads"]} threads, '
              f'peak +{r["peak_extra_mib"]:.0f} MiB ({r["peak_kind"]}; the '
              f'paper: {TABLE6[1.0][2]} on an A10 GPU)')


def report_lift(args):
    """Run the four lift-pool children and print the comparison."""
    results = [
        _child(args, mode) for mode in ('naive', 'fused', 'naive-backward',
                                        'fused-backward')
    ]
    print(f'lift-pool on the {results[0]["geometry"]}:')
    print(f'{"mode":16s} {"points":>9s} {"C":>4s} {"voxels":>8s} '
          f'{"peak MiB":>9s} {"time s":>7s}')
    for r in results:
        print(f'{r["mode"]:16s} {r["points"]:9d} {r["channels"]:4d} '
              f'{r["occupied_voxels"]:8d} {r["peak_extra_mib"]:9.1f} '
              f'{r["seconds"]:7.2f}')
    r0 = results[0]
    print(f'naive (points x C) feature tensor alone: '
          f'{r0["naive_feature_tensor_mib"]:.1f} MiB; pooled rows of the '
          f'{r0["occupied_voxels"]} occupied voxels: {r0["output_mib"]:.1f} '
          f'MiB (a dense volume of all {r0["voxels"]} voxels would be '
          f'{r0["dense_volume_mib"]:.1f} MiB)')
    for fwd, name in ((0, 'forward'), (2, 'forward+backward')):
        ratio = results[fwd + 1]['peak_extra_mib'] / max(
            results[fwd]['peak_extra_mib'], 1e-9)
        print(f'fused / naive peak memory ({name}): {ratio:.3f}')


if __name__ == '__main__':
    main()
