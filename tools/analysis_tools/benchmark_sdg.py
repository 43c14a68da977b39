"""Benchmark SDG-OCC: what the SDG lift and FOAD see on real geometry.

On samples of a (synthetic) nuScenes-format world and on the real nuScenes
key frame of ``--real-sample`` (no sweeps, no lidarseg), with the
paper-size Occ3D configs (6 cameras, 256x704 images, 0.5 m depth bins,
200x200 BEV) and random weights (none of the counts depends on them):

1. Lift (Fig. 2 of the paper): points lifted per image by plain LSS (every
   feature pixel x every depth bin) and by SDG (the 2 l + 1 virtual points
   of every pixel with a diffused depth), and the BEV cells that receive a
   feature: LSS, SDG's virtual points alone, SDG with the LSS fallback.
2. Semantic diffusion (eqs. 1-2): feature cells without a key-frame LiDAR
   return that get a depth, with a 2D head that fits targets marking
   unlabelled cells as class 0 ("before" the fixes of 2026-11-23,
   3d5dd6a) or ignoring them and predicting the class the camera sees
   there ("after"; the synthetic world's rendered classes, an oracle).
   The real sample has no labels: there, one class everywhere gives what
   the geometry allows (the most any semantic map could fill), also
   reported for the synthetic world.
3. FOAD regions (eqs. 5-7): N_AR, N_IR and rho = N_AR / N_IR with the
   LiDAR BEV (cells holding a point) and each lift's camera coverage, and
   the share of IR cells next to a covered cell (within the reach of
   ``camera_bev_conv``'s 3x3 kernel; the others get BN's shift only).
4. FOAD gradient (synthetic, tiny SDG-KL config): loss_distill and the
   gradient of the camera branch for beta in {0, 1, 1000}, distilled at
   the pooled BEV (before 3d5dd6a: the gradient does not depend on beta)
   and at ``camera_bev_conv``'s output (after).
5. Forward latency (``mode='predict'``) of SDG-Fusion against SDG-KL,
   median of ``--repeats`` (0 skips it).

Example::

    python tools/dataset_converters/create_synthetic_nuscenes.py \\
        data/synthetic_nuscenes
    python tools/create_data.py nuscenes \\
        --root-path data/synthetic_nuscenes --version v1.0-mini
    python tools/analysis_tools/benchmark_sdg.py --data-root \\
        data/synthetic_nuscenes/ \\
        --real-sample ../shared/data/nuscenes_real_sample

Like the other tools it imports no plugin code itself: the configs'
``custom_imports`` register and provide it (and
``projects.occ_common.synthetic`` gives the synthetic oracle).
"""
import argparse
import glob
import json
import os.path as osp
import statistics

import numpy as np
import torch
import torch.nn.functional as F
from mmdet3d.registry import DATASETS, MODELS, TRANSFORMS
from mmengine.config import Config
from mmengine.registry import init_default_scope
from mmengine.utils import import_modules_from_strings

from projects.occ_common.analysis.benchmarking import timed_runs
from projects.occ_common.fileio.safe_pickle import load_info_file

ROOT = osp.dirname(
    osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIGS = dict(
    fusion='configs/sdg_occ/sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py',
    kl='configs/sdg_occ/sdgocc-kl_r50_4xb2-24e_occ3d-nus.py',
    tiny_kl='configs/sdg_occ/sdgocc-kl_tiny_1xb1-6e_occ3d-nus-synthetic.py')
#: Pipeline steps that need labels the real sample does not have.
LABEL_STEPS = ('LoadLidarSegLabels', 'LoadOccupancyGT', 'OccBEVAug',
               'PointsToSemanticMaps')


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        '--data-root',
        default='data/synthetic_nuscenes/',
        help='nuScenes-format world with nuscenes_occ_infos_val.pkl')
    parser.add_argument(
        '--real-sample', help='folder of one real nuScenes key frame (an '
        'mmdet3d v2 info .pkl, its .pcd.bin and six images)')
    parser.add_argument(
        '--num-samples', type=int, default=3, help='samples to count on')
    parser.add_argument(
        '--repeats', type=int, default=3, help='timed forwards per model')
    parser.add_argument('--device', default='cpu', help='cpu or cuda')
    parser.add_argument(
        '--threads', type=int, default=0, help='torch CPU threads (0: keep)')
    parser.add_argument('--out', help='write the results as JSON here')
    return parser.parse_args(argv)


def load_cfg(variant, data_root):
    """A config without downloads, pointed at ``data_root``."""
    cfg = Config.fromfile(osp.join(ROOT, CONFIGS[variant]))
    cfg.model.img_backbone.init_cfg = None
    cfg.test_dataloader.dataset.data_root = data_root
    return cfg


def real_sample(cfg, folder):
    """The real key frame through the config's test pipeline (no labels).

    Returns:
        dict: ``inputs`` and ``data_samples`` as a dataset item.
    """
    (pkl, ) = glob.glob(osp.join(glob.escape(folder), '*.pkl'))
    # A downloaded info file: the restricted unpickler, as everywhere.
    info = load_info_file(pkl)['data_list'][0]
    lidar = info['lidar_points']
    lidar['lidar_path'] = osp.join(folder, lidar['lidar_path'])
    info.update(
        lidar_path=lidar['lidar_path'],
        num_pts_feats=lidar['num_pts_feats'],
        lidar2ego=np.asarray(lidar['lidar2ego']),
        ego2global=np.asarray(info['ego2global']),
        lidar_sweeps=[])
    for cam in info['images'].values():
        cam['img_path'] = osp.join(folder, cam['img_path'])
    steps = [
        TRANSFORMS.build(step)
        for step in cfg.test_dataloader.dataset.pipeline
        if step['type'] not in LABEL_STEPS
    ]
    for step in steps:
        info = step(info)
    return info


def lift_stats(sdg, vt_cfg, sample, points, seg_map):
    """Points lifted per image and BEV cells covered by each lift.

    Args:
        sdg (module): ``projects.sdg_occ``.
        vt_cfg (dict): The view transform as the detector builds it.
        sample (Det3DDataSample): Camera metainfo.
        points (Tensor): The sample's points (time lag in column 4).
        seg_map (Tensor): Class of every feature cell. Shape (N, h, w).

    Returns:
        tuple[dict, dict]: The numbers and the camera BEV masks (1, 1, Y,
        X) of ``lss``, ``sdg`` and ``sdg+lss``.
    """
    num_cams, feat_h, feat_w = seg_map.shape
    height, width = sample.metainfo['img_shape']
    lidar2img = torch.as_tensor(sample.metainfo['lidar2img'])[None].float()
    num_bins = sdg.SDGViewTransform(**vt_cfg).num_bins
    context = torch.ones(num_cams, 1, feat_h, feat_w)
    prob = torch.full((num_cams, num_bins, feat_h, feat_w), 1.0 / num_bins)
    logits = F.one_hot(seg_map, 17).permute(0, 3, 1, 2).float()
    stats, masks = {}, {}
    for name, delta in (('lss', dict(use_sdg=False)),
                        ('sdg', dict(fallback='none')), ('sdg+lss', {})):
        out = sdg.SDGViewTransform(**dict(vt_cfg, **delta))(
            context, prob, logits, [points], lidar2img, (height, width), [4])
        masks[name] = out['bev_mask']
        stats[f'{name}_bev_cells'] = int(out['bev_mask'].sum())
        stats[f'{name}_pooled_per_image'] = int(
            out['num_sdg_points'] + out['num_lss_points']) / num_cams
        if name == 'sdg':
            ext = out['ext_depth']
            depths = sdg.virtual_point_depths(ext, vt_cfg['layer_radius'],
                                              vt_cfg['num_layers'])
            made = ((depths > 0) & (ext > 0)[:, None]).sum()
            stats['sdg_points_per_image'] = int(made) / num_cams
            stats['pixels_with_depth_per_image'] = int(
                (ext > 0).sum()) / num_cams
    stats['lss_points_per_image'] = feat_h * feat_w * num_bins
    stats['pixels_per_image'] = feat_h * feat_w
    return stats, masks


def fill_stats(sdg, sparse, radius, heads):
    """Feature cells without a return that the diffusion gives a depth."""
    return {
        name: int(((sdg.semantic_depth_diffusion(sparse, head, radius) > 0)
                   & (sparse == 0)).sum())
        for name, head in heads.items()
    }


def region_stats(points, grid, cam_masks):
    """N_AR, N_IR, rho per lift, and IR cells next to camera coverage."""
    xmin, ymin, zmin, xmax, ymax, zmax = grid['point_cloud_range']
    num_y, num_x = grid['bev_shape']
    xyz = points[:, :3]
    inside = ((xyz[:, 0] >= xmin) & (xyz[:, 0] < xmax) & (xyz[:, 1] >= ymin)
              & (xyz[:, 1] < ymax) & (xyz[:, 2] >= zmin)
              & (xyz[:, 2] < zmax))
    ix = ((xyz[inside, 0] - xmin) / ((xmax - xmin) / num_x)).long()
    iy = ((xyz[inside, 1] - ymin) / ((ymax - ymin) / num_y)).long()
    lidar = torch.zeros(1, 1, num_y, num_x, dtype=torch.bool)
    lidar[0, 0, iy.clamp(max=num_y - 1), ix.clamp(max=num_x - 1)] = True
    stats = dict(lidar_cells=int(lidar.sum()))
    for name, cam in cam_masks.items():
        active, inactive = lidar & cam, lidar & ~cam
        n_ar, n_ir = int(active.sum()), int(inactive.sum())
        stats[name] = dict(
            n_ar=n_ar, n_ir=n_ir, rho=n_ar / max(n_ir, 1),
            ir_share=n_ir / max(int(lidar.sum()), 1),
            # How many of the camera's cells hold a LiDAR return.
            camera_cells_on_lidar=n_ar / max(int(cam.sum()), 1))
        for reach in (1, 2):
            near = F.max_pool2d(cam.float(), 2 * reach + 1, 1, reach).bool()
            stats[name][f'ir_within_{reach}_cell'] = int(
                (inactive & near).sum()) / max(n_ir, 1)
    return stats


def count_sample(sdg, vt_cfg, grid, item, seg_maps):
    """Lift, fill and region numbers of one dataset item."""
    sample = item['data_samples']
    points = item['inputs']['points']
    key = points[points[:, 4] == 0]
    num_cams, feat_h, feat_w = next(iter(seg_maps.values())).shape
    height, width = sample.metainfo['img_shape']
    sparse = sdg.points_to_depth_maps(
        [key], torch.as_tensor(sample.metainfo['lidar2img'])[None].float(),
        (height, width), (feat_h, feat_w))
    lift, masks = lift_stats(sdg, vt_cfg, sample, points, seg_maps['lift'])
    fill = fill_stats(sdg, sparse, vt_cfg['diffusion_radius'], seg_maps)
    fill.pop('lift')
    fill.update(cells=sparse.numel(), co_points=int((sparse > 0).sum()))
    return dict(
        lift=lift, fill=fill, regions=region_stats(points, grid, masks))


def synthetic_seg_maps(sdg, testing, data_root, item, stride):
    """Heads of item 2: fitted to old / new targets, and one class."""
    sample = item['data_samples']
    gt_depth = sample.gt_depth.float()
    gt_seg = sample.gt_seg_2d.long()
    old = sdg.downsample_seg_labels(gt_seg, gt_depth, stride, empty_label=0)
    new = sdg.downsample_seg_labels(gt_seg, gt_depth, stride)
    oracle = testing.sample_feature_classes(data_root, sample, stride)
    after = torch.where(new == 255, oracle, new)
    return dict(before=old, after=after, geometry=torch.ones_like(old),
                lift=after)


def beta_gradients(cfg, data_root):
    """FOAD's loss and camera gradient against beta (tiny SDG-KL)."""
    cfg.test_dataloader.dataset.data_root = data_root
    item = DATASETS.build(cfg.test_dataloader.dataset)[0]
    torch.manual_seed(0)
    model = MODELS.build(cfg.model).train()
    data = model.data_preprocessor(
        dict(inputs={k: [v] for k, v in item['inputs'].items()},
             data_samples=[item['data_samples']]), True)
    inputs, samples = data['inputs'], data['data_samples']
    _, cam = model.extract_camera_bev(inputs, samples)
    lidar = model.extract_lidar_bev(inputs)
    fused = model.fuse(lidar, cam).detach()
    params = [p for part in ('img_backbone', 'img_neck', 'depth_net',
                             'camera_bev_conv')
              for p in getattr(model, part).parameters()]
    loss_cls = type(model.loss_distill)
    out = {}
    for student in ('bev_pooled', 'bev'):
        grads = {}
        for alpha, beta in ((1.0, 0.0), (1.0, 1.0), (1.0, 1000.0),
                            (0.0, 1.0)):
            loss = loss_cls(alpha=alpha, beta=beta)(
                cam[student], fused, lidar['bev_mask'], cam['bev_mask'])
            grad = torch.autograd.grad(
                loss, params, retain_graph=True, allow_unused=True)
            grads[(alpha, beta)] = (loss.item(), torch.cat([
                (g if g is not None else torch.zeros_like(p)).flatten()
                for g, p in zip(grad, params)
            ]))
        base = grads[(1.0, 0.0)][1]
        out[student] = {
            f'alpha{a:g}_beta{b:g}': dict(
                loss=value, grad_norm=float(g.norm()),
                grad_change_from_beta0=float((g - base).norm()))
            for (a, b), (value, g) in grads.items() if a == 1.0
        }
        out[student]['ir_only_grad_norm'] = float(grads[(0.0, 1.0)][1].norm())
    return out


def time_forward(model, item, repeats, device):
    """Median and min forward time (ms) of ``mode='predict'``."""
    data = model.data_preprocessor(
        dict(inputs={k: [v] for k, v in item['inputs'].items()},
             data_samples=[item['data_samples']]), False)
    inputs = data['inputs']
    inputs['points'] = [p.to(device) for p in inputs['points']]
    with torch.no_grad():
        runs = timed_runs(
            lambda: model(inputs, data['data_samples'], mode='predict'),
            repeats, warmup=1, device=device)
    times = [1000 * t for t in runs['wall_s']]
    return dict(median_ms=statistics.median(times), min_ms=min(times))


def main(argv=None):
    """Run the measurements and print a summary."""
    args = parse_args(argv)
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    if not osp.isfile(osp.join(args.data_root,
                               'nuscenes_occ_infos_val.pkl')):
        raise FileNotFoundError(
            f'{args.data_root} has no nuscenes_occ_infos_val.pkl; build the '
            'synthetic world first (see this script\'s docstring)')
    cfg = load_cfg('fusion', args.data_root)
    modules = import_modules_from_strings(**cfg.custom_imports)
    sdg = modules[-1]
    testing = import_modules_from_strings(
        'projects.occ_common.synthetic.camera_classes')
    init_default_scope(cfg.default_scope)
    model = MODELS.build(cfg.model)
    vt = model.view_transform
    grid = dict(point_cloud_range=vt.point_cloud_range,
                bev_shape=vt.bev_shape)
    vt_cfg = dict(cfg.model.view_transform, depth_bound=vt.depth_bound,
                  **grid)
    vt_cfg.pop('type')
    stride = model.downsample
    dataset = DATASETS.build(cfg.test_dataloader.dataset)
    result = dict(synthetic=[], config=CONFIGS['fusion'])
    for index in range(min(args.num_samples, len(dataset))):
        item = dataset[index]
        maps = synthetic_seg_maps(sdg, testing, args.data_root, item, stride)
        result['synthetic'].append(
            count_sample(sdg, vt_cfg, grid, item, maps))
    if args.real_sample:
        item = real_sample(cfg, args.real_sample)
        height, width = item['data_samples'].metainfo['img_shape']
        ones = torch.ones(6, height // stride, width // stride,
                          dtype=torch.long)
        result['real'] = count_sample(
            sdg, vt_cfg, grid, item,
            dict(before=torch.zeros_like(ones), geometry=ones, lift=ones))
    result['beta'] = beta_gradients(
        load_cfg('tiny_kl', args.data_root), args.data_root)
    if args.repeats > 0:
        models = {v: MODELS.build(load_cfg(v, args.data_root).model).to(
            args.device).eval() for v in ('fusion', 'kl')}
        result['latency'] = {
            v: time_forward(m, dataset[0], args.repeats, args.device)
            for v, m in models.items()
        }
    print_summary(result)
    if args.out:
        with open(args.out, 'w') as f:
            json.dump(result, f, indent=1)
    return result


def _mean(samples, *keys):
    values = []
    for sample in samples:
        for key in keys:
            sample = sample[key]
        values.append(sample)
    return statistics.mean(values)


def print_summary(result):
    """One line per measurement: synthetic mean, then the real sample."""
    parts = [('synthetic', result['synthetic'])]
    if 'real' in result:
        parts.append(('real', [result['real']]))
    for name, samples in parts:
        lift = lambda key: _mean(samples, 'lift', key)  # noqa: E731
        print(f'[{name}, {len(samples)} sample(s)] per image: LSS lifts '
              f"{lift('lss_points_per_image'):.0f} points "
              f"({lift('lss_pooled_per_image'):.0f} in the grid), SDG "
              f"{lift('sdg_points_per_image'):.0f} virtual points "
              f"({lift('sdg_pooled_per_image'):.0f} in the grid) from "
              f"{lift('pixels_with_depth_per_image'):.0f} of "
              f"{lift('pixels_per_image'):.0f} pixels")
        print(f'[{name}] BEV cells with a feature (of 40000): LSS '
              f"{lift('lss_bev_cells'):.0f}, SDG alone "
              f"{lift('sdg_bev_cells'):.0f}, SDG + LSS fallback "
              f"{lift('sdg+lss_bev_cells'):.0f}")
        fill = {k: _mean(samples, 'fill', k) for k in samples[0]['fill']}
        empty = fill['cells'] - fill['co_points']
        print(f'[{name}] diffusion fill: of {fill["cells"]:.0f} cells '
              f'{empty:.0f} have no key-frame return; filled '
              + ', '.join(f'{k} {fill[k]:.0f} ({100 * fill[k] / empty:.1f}'
                          ' %)' for k in ('before', 'after', 'geometry')
                          if k in fill))
        for lift_name in ('lss', 'sdg', 'sdg+lss'):
            reg = {k: _mean(samples, 'regions', lift_name, k)
                   for k in samples[0]['regions'][lift_name]}
            near = (100 * reg['ir_within_1_cell'],
                    100 * reg['ir_within_2_cell'])
            print(f'[{name}] FOAD regions with the {lift_name} camera BEV: '
                  f"N_AR {reg['n_ar']:.0f}, N_IR {reg['n_ir']:.0f} "
                  f"({100 * reg['ir_share']:.1f} % of the LiDAR cells), "
                  f"rho {reg['rho']:.2f}; camera cells on LiDAR "
                  f"{100 * reg['camera_cells_on_lidar']:.1f} %; IR within 1"
                  f' / 2 cells of the camera {near[0]:.1f} / {near[1]:.1f}'
                  ' %')
    for student, runs in result['beta'].items():
        print(f'[beta, tiny SDG-KL] student {student}: ' + '; '.join(
            f"{k}: loss {v['loss']:.3g}, |grad| {v['grad_norm']:.3g}, "
            f"|grad - grad(beta 0)| {v['grad_change_from_beta0']:.3g}"
            for k, v in runs.items() if k.startswith('alpha'))
              + f"; IR only (alpha 0): |grad| {runs['ir_only_grad_norm']:.3g}")
    for variant, timing in result.get('latency', {}).items():
        print(f'[latency] {variant}: median {timing["median_ms"]:.0f} ms, '
              f'min {timing["min_ms"]:.0f} ms')


if __name__ == '__main__':
    main()
