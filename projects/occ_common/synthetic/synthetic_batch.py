"""Random batches of a config's shapes, as its dataloader gives them.

A collated ``dict(inputs, data_samples)`` for a config without its data:
images of ``img_size`` from a ring of ``cam_names`` cameras, LiDAR-like
clouds with sweep time lags, and (on request) occupancy, depth and 2-D
semantic targets. ``tools/analysis_tools/benchmark.py --synthetic-batch``
times models on them; ``tools/analysis_tools/ddp_check.py`` trains on them.
"""
import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch
from mmengine.config import Config

#: Points of one nuScenes LiDAR sweep (32 beams, 20 Hz), on average.
NUSCENES_SWEEP_POINTS = 34720


def lidar_like_cloud(num_points: int, pc_range, dims: int,
                     gen: np.random.Generator) -> np.ndarray:
    """Returns of a spinning 32-beam LiDAR 1.84 m above the ground.

    Each ray (random azimuth, one of 32 elevations from -30.67 to 10.67
    degrees) hits a wall of its 1-degree sector (4-45 m away, 1-8 m tall)
    or the ground z = -1.84 m, whichever is first, so the points lie on
    surfaces as real returns do (uniform points would fill far more voxels
    than a real sweep). Points outside ``pc_range`` are dropped and drawn
    again.

    Returns:
        np.ndarray: Shape (num_points, dims), float32; x, y, z, then
        intensity in [0, 1) and zeros.
    """
    lo, hi = np.asarray(pc_range[:3]), np.asarray(pc_range[3:])
    wall_dist = gen.uniform(4.0, 45.0, 360)
    wall_top = gen.uniform(1.0, 8.0, 360) - 1.84
    beams = np.radians(np.linspace(-30.67, 10.67, 32))
    found: List[np.ndarray] = []
    count = 0
    while count < num_points:
        azimuth = gen.uniform(0, 2 * math.pi, 2 * num_points)
        elevation = beams[gen.integers(0, 32, 2 * num_points)]
        sector = (np.degrees(azimuth).astype(int)) % 360
        tan_el = np.tan(elevation)
        ground = np.where(tan_el < 0, -1.84 / np.minimum(tan_el, -1e-6),
                          np.inf)
        hits_wall = wall_dist[sector] * tan_el <= wall_top[sector]
        dist = np.where(hits_wall, np.minimum(wall_dist[sector], ground),
                        ground)
        xyz = np.stack([
            dist * np.cos(azimuth), dist * np.sin(azimuth), dist * tan_el
        ], axis=1)
        keep = np.isfinite(dist) & (xyz >= lo).all(1) & (xyz < hi).all(1)
        found.append(xyz[keep])
        count += int(keep.sum())
    xyz = np.concatenate(found)[:num_points]
    extra = np.zeros((num_points, max(0, dims - 3)))
    if dims > 3:
        extra[:, 0] = gen.random(num_points)
    return np.concatenate([xyz, extra], axis=1).astype(np.float32)


def with_sweep_time(points: np.ndarray, sweeps: int) -> np.ndarray:
    """Split a cloud into ``sweeps`` equal sweeps by its time column.

    Column 4 becomes the time lag of nuScenes' 20 Hz sweeps: 0 for the
    first ``ceil(P / sweeps)`` points (the key frame), 0.05 s for the
    next as many, and so on.

    Args:
        points (np.ndarray): Shape (P, >= 5).
        sweeps (int): Key frame plus merged sweeps.

    Returns:
        np.ndarray: The same array, column 4 rewritten.
    """
    per_sweep = max(1, math.ceil(len(points) / sweeps))
    points[:, 4] = 0.05 * (np.arange(len(points)) // per_sweep)
    return points


def ring_rig(num_cams: int, img_size: Tuple[int, int]) -> Dict[str, list]:
    """Cameras round the LiDAR looking outwards, 70 degree field of view.

    Returns:
        dict: ``cam2img``, ``lidar2cam``, ``lidar2img`` and
        ``img_aug_matrix`` (identity), each Shape (N, 4, 4).
    """
    height, width = img_size
    focal = width / 2 / math.tan(math.radians(35))
    cam2img = np.tile(np.eye(4), (num_cams, 1, 1))
    cam2img[:, 0, 0] = cam2img[:, 1, 1] = focal
    cam2img[:, 0, 2], cam2img[:, 1, 2] = width / 2, height / 2
    lidar2cam = np.tile(np.eye(4), (num_cams, 1, 1))
    for k in range(num_cams):
        yaw = 2 * math.pi * k / num_cams
        # Rows: the camera's right, down and forward axes (OpenCV).
        lidar2cam[k, :3, :3] = [[math.sin(yaw), -math.cos(yaw), 0],
                                [0, 0, -1], [math.cos(yaw), math.sin(yaw), 0]]
    aug = np.tile(np.eye(4), (num_cams, 1, 1))
    return dict(
        cam2img=cam2img.astype(np.float32),
        lidar2cam=lidar2cam.astype(np.float32),
        lidar2img=(aug @ cam2img @ lidar2cam).astype(np.float32),
        img_aug_matrix=aug.astype(np.float32))


def synthetic_batch(cfg: Config,
                    batch_size: int,
                    num_points: Optional[int],
                    labels: bool = False,
                    seed: int = 0) -> Tuple[dict, str]:
    """A collated batch of random data of the config's shapes.

    Uses the config's ``cam_names`` and ``img_size`` (images),
    ``point_cloud_range`` and ``sweeps_num`` (points) and ``grid_size`` /
    ``voxel_size`` (GT grid and its metainfo), as the dataset configs in
    ``configs/_base_/datasets`` define them. A model with ``num_frames``
    T > 1 gets T x N images and the T - 1 previous key frames'
    metainfo as ``LoadPreviousKeyFrames`` packs it, of a car that has not
    moved: the same camera rig, ``prev2curr`` the identity, and one fresh
    key-frame cloud per previous frame.

    Args:
        cfg (Config): The config.
        batch_size (int): Samples.
        num_points (int, optional): Points per cloud.
        labels (bool): Training targets: ``gt_occ`` with
            :func:`synthetic_labels` instead of all empty, a ``gt_depth``
            map per image (:func:`synthetic_depth`), and where the model
            asks for them its ``loss_mask_key`` mask, ``gt_seg_2d``
            (:func:`synthetic_seg_2d`) and point labels
            (:func:`synthetic_point_labels`). Defaults to False.
        seed (int): Of the random generator (e.g. one batch per DDP rank).
            Defaults to 0.

    Returns:
        tuple[dict, str]: The batch (``inputs`` and ``data_samples``, as
        the dataloader gives them) and a description of its size.

    Raises:
        ValueError: If the config declares neither images nor points.
    """
    from mmdet3d.structures import Det3DDataSample
    gen = np.random.default_rng(seed)
    has_imgs = cfg.get('cam_names') and cfg.get('img_size')
    pc_range = cfg.get('point_cloud_range')
    if not has_imgs and pc_range is None:
        raise ValueError(f'--synthetic-batch: {cfg.filename} declares '
                         'neither cam_names / img_size nor '
                         'point_cloud_range.')
    if num_points is None:
        num_points = NUSCENES_SWEEP_POINTS * (cfg.get('sweeps_num', 0) + 1)
    inputs: Dict[str, list] = {}
    described = []
    meta = dict(lidar2ego=np.eye(4, dtype=np.float32),
                ego2global=np.eye(4, dtype=np.float32),
                bda_matrix=np.eye(4, dtype=np.float32))
    frames = int(cfg.model.get('num_frames', 1))
    if has_imgs:
        num_cams, (height, width) = len(cfg.cam_names), cfg.img_size
        inputs['img'] = [
            torch.from_numpy(
                gen.integers(0, 256, (frames * num_cams, 3, height, width),
                             dtype=np.uint8)) for _ in range(batch_size)
        ]
        rig = ring_rig(num_cams, (height, width))
        meta.update(rig)
        if frames > 1:
            meta.update({
                f'prev_{key}': np.stack([rig[key]] * (frames - 1))
                for key in ('cam2img', 'lidar2cam', 'img_aug_matrix',
                            'lidar2img')
            })
            meta.update(prev2curr=np.tile(np.eye(4), (frames - 1, 1, 1)))
            described.append(f'{frames} frames')
        meta.update(img_shape=(height, width), ori_shape=(height, width),
                    pad_shape=(height, width), num_views=num_cams,
                    cam_names=list(cfg.cam_names))
        described.append(f'{num_cams}x{height}x{width} images')
    if pc_range is not None:
        sweeps = cfg.get('sweeps_num', 0) + 1
        inputs['points'] = [
            torch.from_numpy(
                with_sweep_time(
                    lidar_like_cloud(num_points, pc_range, 5, gen), sweeps))
            for _ in range(batch_size)
        ]
        meta.update(occ_pc_range=np.asarray(pc_range, np.float32))
        if sweeps > 1:
            # As LoadOccPointsFromMultiSweeps marks them: what uses the key
            # frame only (SDG's depth guidance) must see one sweep, not all.
            meta.update(points_time_dim=4)
        described.append(f'{num_points} points in {sweeps} sweeps')
    grid = cfg.get('grid_size')
    samples = []
    for index in range(batch_size):
        sample = Det3DDataSample(metainfo=dict(meta, sample_idx=index))
        if frames > 1:
            sample.set_metainfo(
                dict(token=f'synthetic-{index}',
                     prev_tokens=[
                         f'synthetic-{index}@t-{k}' for k in range(1, frames)
                     ]))
            if pc_range is not None:
                sample.set_metainfo(
                    dict(prev_points=[
                        with_sweep_time(
                            lidar_like_cloud(num_points // sweeps, pc_range,
                                             5, gen), 1)
                        for _ in range(1, frames)
                    ]))
        head = cfg.model.get('point_seg_head')
        if labels and head and 'points' in inputs:
            sample.gt_pts_seg = synthetic_point_labels(
                inputs['points'][index], head['num_classes'], gen)
        if labels and has_imgs:
            sample.gt_depth = synthetic_depth(num_cams, cfg.img_size, gen)
            if cfg.model.get('loss_seg') is not None:
                sample.gt_seg_2d = synthetic_seg_2d(
                    sample.gt_depth, cfg.model.depth_net.seg_channels, gen)
        if grid is not None:
            sample.gt_occ = (synthetic_labels(grid, cfg, gen) if labels else
                             torch.zeros(tuple(grid), dtype=torch.long))
            mask_key = cfg.model.get('loss_mask_key')
            if labels and mask_key:
                # Occ3D's camera mask: a random half of the grid.
                sample.set_field(
                    torch.from_numpy(gen.random(tuple(grid)) < 0.5),
                    mask_key)
            sample.set_metainfo(
                dict(occ_voxel_size=np.asarray(cfg.voxel_size, np.float32)))
            described.append('x'.join(str(g) for g in grid) + ' grid')
        samples.append(sample)
    description = f'synthetic: {", ".join(dict.fromkeys(described))}'
    return dict(inputs=inputs, data_samples=samples), description


def synthetic_labels(grid: Sequence[int], cfg: Config,
                     gen: np.random.Generator) -> torch.Tensor:
    """Occupancy labels like SurroundOcc's: mostly empty, every class.

    90 % of the voxels are the config's ``empty_index`` (0 by default),
    the rest a uniform random class, so that every class is present (the
    Lovasz and scene-class-affinity terms do the most work).

    Returns:
        Tensor: int64. Shape (X, Y, Z).
    """
    num_classes = cfg.model.get('num_classes', 2)
    empty = cfg.model.get('empty_index', 0)
    occ = gen.integers(0, num_classes, tuple(grid))
    occ[gen.random(tuple(grid)) < 0.9] = empty
    return torch.from_numpy(occ)


def synthetic_depth(num_cams: int, img_size: Sequence[int],
                    gen: np.random.Generator) -> torch.Tensor:
    """Sparse LiDAR depth maps: 2 % of the pixels at 1-60 m, 0 elsewhere
    (a 10-sweep cloud covers a few per cent of a nuScenes image).

    Returns:
        Tensor: float32. Shape (N, H, W).
    """
    shape = (num_cams, *img_size)
    depth = gen.uniform(1.0, 60.0, shape).astype(np.float32)
    depth[gen.random(shape) >= 0.02] = 0.0
    return torch.from_numpy(depth)


def synthetic_seg_2d(depth: torch.Tensor, num_classes: int,
                     gen: np.random.Generator) -> torch.Tensor:
    """2-D semantic targets as ``PointsToSemanticMaps`` makes them: a
    uniform random class in 1..``num_classes`` - 1 at every pixel with a
    LiDAR depth, the ignore label 255 elsewhere.

    Args:
        depth (Tensor): From :func:`synthetic_depth`. Shape (N, H, W).
        num_classes (int): 2-D classes, 0 ("no class") included.

    Returns:
        Tensor: uint8. Shape (N, H, W).
    """
    seg = gen.integers(1, num_classes, tuple(depth.shape)).astype(np.uint8)
    seg[depth.numpy() <= 0] = 255
    return torch.from_numpy(seg)


def synthetic_point_labels(points: torch.Tensor, num_classes: int,
                           gen: np.random.Generator):
    """Point labels as ``LoadLidarSegLabels`` gives them: a uniform random
    class in 1..``num_classes`` - 1 per key-frame point (time lag 0 in
    column 4, or every point without one), the ignore label 255 on the
    sweeps' points.

    Args:
        points (Tensor): One cloud. Shape (P, C).
        num_classes (int): Point classes, 0 ("no class") included.

    Returns:
        PointData: ``pts_semantic_mask``, int64 (P,).
    """
    from mmdet3d.structures import PointData
    labels = gen.integers(1, num_classes, len(points))
    if points.shape[1] > 4:
        labels[points[:, 4].numpy() != 0] = 255
    return PointData(pts_semantic_mask=torch.from_numpy(labels))
