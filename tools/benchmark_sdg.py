"""Benchmark SDG-OCC: lifted points of SDG vs plain LSS, Fusion vs KL speed.

Two measurements on samples of a (synthetic) nuScenes-format world, with
the paper-size Occ3D configs (6 cameras, 256x704 images):

1. Points lifted by the view transform per sample: the plain LSS lift
   (every feature pixel x every depth bin) against SDG's virtual points
   (pixels with a diffused LiDAR depth x ``num_layers``), alone
   (``fallback='none'``) and with the LSS fallback of the other pixels.
   The counts do not depend on the network weights; the semantic map is the
   oracle one (the 2D labels of the sample, downsampled as in training).
2. Forward latency (``mode='predict'``) of SDG-Fusion against SDG-KL with
   random weights, median over repeats; SDG-KL skips the SPVCNN branch and
   the fusion at inference.

Example::

    python tools/create_synthetic_nuscenes.py data/synthetic_nuscenes
    python tools/create_data.py nuscenes \\
        --root-path data/synthetic_nuscenes --version v1.0-mini
    python tools/benchmark_sdg.py --data-root data/synthetic_nuscenes/

Like the other tools it imports no plugin code itself: the configs'
``custom_imports`` register and provide it.
"""
import argparse
import json
import os.path as osp
import statistics

import torch
import torch.nn.functional as F
from mmdet3d.registry import DATASETS, MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope
from mmengine.utils import import_modules_from_strings

from projects.occ_common.utils.benchmarking import timed_runs

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
CONFIGS = dict(
    fusion='configs/sdg_occ/sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py',
    kl='configs/sdg_occ/sdgocc-kl_r50_4xb2-24e_occ3d-nus.py')


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        '--data-root',
        default='data/synthetic_nuscenes/',
        help='nuScenes-format world with nuscenes_occ_infos_val.pkl')
    parser.add_argument(
        '--num-samples', type=int, default=4, help='samples to count on')
    parser.add_argument(
        '--repeats', type=int, default=5, help='timed forwards per model')
    parser.add_argument('--device', default='cpu', help='cpu or cuda')
    parser.add_argument(
        '--threads', type=int, default=0, help='torch CPU threads (0: keep)')
    parser.add_argument('--out', help='write the results as JSON here')
    return parser.parse_args(argv)


def load_cfg(variant, data_root):
    """A paper-size config without downloads, pointed at ``data_root``."""
    cfg = Config.fromfile(osp.join(ROOT, CONFIGS[variant]))
    cfg.model.img_backbone.init_cfg = None
    cfg.test_dataloader.dataset.data_root = data_root
    return cfg


def batches(cfg, model, num_samples, device):
    """Preprocessed single-sample batches of the test split."""
    dataset = DATASETS.build(cfg.test_dataloader.dataset)
    for index in range(min(num_samples, len(dataset))):
        item = dataset[index]
        data = dict(
            inputs={k: [v]
                    for k, v in item['inputs'].items()},
            data_samples=[item['data_samples']])
        data = model.data_preprocessor(data, False)
        inputs = data['inputs']
        inputs['points'] = [p.to(device) for p in inputs['points']]
        yield inputs, data['data_samples']


def count_points(cfg, model, sdg_module, inputs, samples, device):
    """Points each lift pools for one sample."""
    # The view transform with the grid and bins the detector gives it.
    built = model.view_transform
    vt_cfg = dict(
        cfg.model.view_transform,
        point_cloud_range=built.point_cloud_range,
        bev_shape=built.bev_shape,
        depth_bound=built.depth_bound)
    imgs = inputs['imgs']
    stride = cfg.model.downsample
    num = imgs.shape[0] * imgs.shape[1]
    feat_shape = (imgs.shape[-2] // stride, imgs.shape[-1] // stride)
    lidar2img = torch.stack([
        torch.as_tensor(s.metainfo['lidar2img']) for s in samples
    ]).float().to(device)
    gt_seg = torch.cat([s.gt_seg_2d for s in samples]).to(device)
    gt_depth = torch.cat([s.gt_depth for s in samples]).to(device)
    labels = sdg_module.downsample_seg_labels(
        gt_seg, gt_depth, stride, empty_label=0)
    num_seg = cfg.model.depth_net.seg_channels
    seg_logits = F.one_hot(labels.clamp(max=num_seg - 1),
                           num_seg).permute(0, 3, 1, 2).float()
    num_bins = model.depth_net.num_depth_bins
    context = torch.ones(num, 1, *feat_shape, device=device)
    prob = torch.full((num, num_bins, *feat_shape), 1.0 / num_bins,
                      device=device)
    counts = {}
    for name, delta in (('lss', dict(use_sdg=False, fallback='lss')),
                        ('sdg', dict(fallback='none')),
                        ('sdg+lss', dict(fallback='lss'))):
        vt = MODELS.build(dict(vt_cfg, **delta)).to(device)
        out = vt(context, prob, seg_logits, inputs['points'], lidar2img,
                 imgs.shape[-2:])
        counts[name] = int(out['num_sdg_points'] + out['num_lss_points'])
        if 'ext_depth' in out:
            counts['pixels_with_depth'] = int((out['ext_depth'] > 0).sum())
    counts['pixels'] = num * feat_shape[0] * feat_shape[1]
    return counts


def time_forward(model, inputs, samples, repeats, device):
    """Forward times (ms) of ``mode='predict'``: median, min and all runs.

    On a shared CPU the minimum is the best estimate of the uncontended
    time; the median is reported with it.
    """

    with torch.no_grad():
        runs = timed_runs(
            lambda: model(inputs, samples, mode='predict'),
            repeats,
            warmup=1,
            device=device)
    times = [1000 * t for t in runs['wall_s']]
    return dict(
        median_ms=statistics.median(times), min_ms=min(times), runs_ms=times)


def main(argv=None):
    """Run both measurements and print a summary."""
    args = parse_args(argv)
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    if not osp.isfile(osp.join(args.data_root,
                               'nuscenes_occ_infos_val.pkl')):
        raise FileNotFoundError(
            f'{args.data_root} has no nuscenes_occ_infos_val.pkl; build the '
            'synthetic world first (see this script\'s docstring)')
    cfgs = {v: load_cfg(v, args.data_root) for v in CONFIGS}
    modules = import_modules_from_strings(**cfgs['fusion'].custom_imports)
    sdg_module = modules[-1]
    init_default_scope(cfgs['fusion'].default_scope)
    models = {
        v: MODELS.build(cfg.model).to(args.device).eval()
        for v, cfg in cfgs.items()
    }

    per_sample = []
    timings = {v: [] for v in models}
    data = list(
        batches(cfgs['fusion'], models['fusion'], args.num_samples,
                args.device))
    for inputs, samples in data:
        with torch.no_grad():
            per_sample.append(
                count_points(cfgs['fusion'], models['fusion'], sdg_module,
                             inputs, samples, args.device))
    inputs, samples = data[0]
    for variant, model in models.items():
        timings[variant] = time_forward(model, inputs, samples,
                                        args.repeats, args.device)

    mean = {
        key: statistics.mean(c[key] for c in per_sample)
        for key in per_sample[0]
    }
    result = dict(
        device=args.device,
        threads=torch.get_num_threads(),
        num_samples=len(per_sample),
        num_points=int(inputs['points'][0].shape[0]),
        points_per_sample=per_sample,
        mean_points=mean,
        sdg_over_lss=mean['sdg'] / max(mean['lss'], 1),
        sdg_lss_over_lss=mean['sdg+lss'] / max(mean['lss'], 1),
        latency=timings,
        fusion_over_kl_median=timings['fusion']['median_ms'] /
        timings['kl']['median_ms'],
        fusion_over_kl_min=timings['fusion']['min_ms'] /
        timings['kl']['min_ms'])
    print(f"Lifted points per sample (mean of {len(per_sample)}): "
          f"plain LSS {mean['lss']:.0f}, SDG virtual only {mean['sdg']:.0f} "
          f"({100 * result['sdg_over_lss']:.1f} % of LSS), SDG + LSS "
          f"fallback {mean['sdg+lss']:.0f} "
          f"({100 * result['sdg_lss_over_lss']:.1f} %); feature pixels "
          f"with a diffused depth: {mean['pixels_with_depth']:.0f} of "
          f"{mean['pixels']:.0f}")
    print(f"Forward latency on {args.device} ({result['threads']} threads, "
          f"{result['num_points']} LiDAR points, min / median of "
          f"{args.repeats}): SDG-Fusion {timings['fusion']['min_ms']:.0f} / "
          f"{timings['fusion']['median_ms']:.0f} ms, SDG-KL "
          f"{timings['kl']['min_ms']:.0f} / {timings['kl']['median_ms']:.0f}"
          f" ms, ratio {result['fusion_over_kl_min']:.2f} / "
          f"{result['fusion_over_kl_median']:.2f} (paper, RTX 4090: 133 / 83"
          f" = {133 / 83:.2f})")
    if args.out:
        with open(args.out, 'w') as f:
            json.dump(result, f, indent=1)


if __name__ == '__main__':
    main()
