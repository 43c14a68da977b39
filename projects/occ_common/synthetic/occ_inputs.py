"""Hand-made camera rigs and tiny occupancy batches for model tests.

The rig is a ring of ``N`` pinhole cameras at the LiDAR origin, camera ``k``
looking along azimuth ``2 * pi * k / N`` with the OpenCV axes (x right,
y down, z forward); the matrices follow the conventions of
``projects.occ_common.models.layers.camera_geometry``.
"""
import math
from typing import List, Sequence, Tuple

import numpy as np
import torch
from torch import Tensor

#: Depth bins of :func:`patch_depth_map`: D = 4 bins [1, 2) [2, 3) [3, 4)
#: [4, 5) m.
PATCH_DEPTH_BOUND = (1.0, 5.0, 1.0)


def patch_depth_map() -> Tensor:
    """A (1, 4, 4) LiDAR depth map of 2 x 2 patches, 0 = no return.

    With :data:`PATCH_DEPTH_BOUND`:

    * top-left     (0, 3.5, 0, 2.2): nearest 2.2 -> bin 1
    * top-right    all 0: no return
    * bottom-left  (7, 6, 0, 0): nearest 6 >= 5 -> dropped
    * bottom-right (1.0, 4.9, 3, 0): nearest 1.0 -> bin 0

    Returns:
        Tensor: Shape (1, 4, 4).
    """
    return torch.tensor([[[0.0, 3.5, 0.0, 0.0], [0.0, 2.2, 0.0, 0.0],
                          [7.0, 6.0, 1.0, 4.9], [0.0, 0.0, 3.0, 0.0]]])


def ring_camera_rig(num_cams: int,
                    img_shape: Sequence[int],
                    focal: float,
                    height: float = 0.0) -> Tuple[Tensor, Tensor]:
    """Cameras around the origin, looking outwards.

    Args:
        num_cams (int): Number of cameras ``N``.
        img_shape (Sequence[int]): ``(H, W)``; the principal point is the
            image centre ``(W / 2, H / 2)``.
        focal (float): Focal length in pixels.
        height (float): Camera height above the LiDAR origin in metres.
            Defaults to 0.

    Returns:
        tuple[Tensor, Tensor]: ``cam2img`` and ``lidar2cam``, each
        Shape (N, 4, 4) float64.
    """
    img_h, img_w = img_shape
    cam2img = torch.eye(4, dtype=torch.float64).repeat(num_cams, 1, 1)
    cam2img[:, 0, 0] = cam2img[:, 1, 1] = focal
    cam2img[:, 0, 2] = img_w / 2
    cam2img[:, 1, 2] = img_h / 2
    lidar2cam = torch.zeros(num_cams, 4, 4, dtype=torch.float64)
    for k in range(num_cams):
        yaw = 2 * math.pi * k / num_cams
        forward = torch.tensor([math.cos(yaw), math.sin(yaw), 0.0])
        right = torch.tensor([math.sin(yaw), -math.cos(yaw), 0.0])
        down = torch.tensor([0.0, 0.0, -1.0])
        rot = torch.stack([right, down, forward]).double()  # rows: cam axes
        centre = torch.tensor([0.0, 0.0, height], dtype=torch.float64)
        lidar2cam[k, :3, :3] = rot
        lidar2cam[k, :3, 3] = -rot @ centre
        lidar2cam[k, 3, 3] = 1.0
    return cam2img, lidar2cam


def sparse_depth_maps(points: Tensor, lidar2img: Tensor,
                      img_shape: Sequence[int]) -> Tensor:
    """Nearest-point depth per pixel, 0 where no point projects.

    Pixel ``i`` covers ``[i, i + 1)``, as in the data pipeline.

    Args:
        points (Tensor): Working-frame points. Shape (P, >=3).
        lidar2img (Tensor): Projections. Shape (N, 4, 4).
        img_shape (Sequence[int]): ``(H, W)``.

    Returns:
        Tensor: Depth maps. Shape (N, H, W) float32.
    """
    img_h, img_w = img_shape
    num_cams = lidar2img.shape[0]
    depth = torch.zeros(num_cams, img_h, img_w, dtype=torch.float64)
    if points.shape[0] == 0:
        return depth.float()
    homo = torch.cat([points[:, :3].double(),
                      torch.ones(points.shape[0], 1, dtype=torch.float64)],
                     dim=1)
    proj = torch.einsum('nij,pj->npi', lidar2img.double(), homo)
    for n in range(num_cams):
        z = proj[n, :, 2]
        front = z > 1e-3
        u = torch.floor(proj[n, front, 0] / z[front]).long()
        v = torch.floor(proj[n, front, 1] / z[front]).long()
        zf = z[front]
        ok = (u >= 0) & (u < img_w) & (v >= 0) & (v < img_h)
        # Far points first so that the nearest one is written last.
        order = torch.argsort(zf[ok], descending=True)
        depth[n, v[ok][order], u[ok][order]] = zf[ok][order]
    return depth.float()


def make_occ_batch(batch_size: int = 1,
                   num_cams: int = 2,
                   img_shape: Sequence[int] = (32, 64),
                   focal: float = 32.0,
                   num_points: Sequence[int] = (40, ),
                   occ_shape: Sequence[int] = (8, 8, 4),
                   pc_range: Sequence[float] = (-8., -8., -2., 8., 8., 2.),
                   num_classes: int = 4,
                   seed: int = 0) -> Tuple[dict, List]:
    """A random batch in the format of the data pipeline and preprocessor.

    Args:
        batch_size (int): ``B``. Defaults to 1.
        num_cams (int): ``N``. Defaults to 2.
        img_shape (Sequence[int]): ``(H, W)``. Defaults to (32, 64).
        focal (float): Focal length in pixels. Defaults to 32.
        num_points (Sequence[int]): Points per sample (cycled over the
            batch; 0 gives an empty cloud). Defaults to (40,).
        occ_shape (Sequence[int]): ``(X, Y, Z)``. Defaults to (8, 8, 4).
        pc_range (Sequence[float]): Range the points are drawn in.
        num_classes (int): Labels drawn in ``[0, num_classes)``, with a few
            255 (ignored). Defaults to 4.
        seed (int): Random seed. Defaults to 0.

    Returns:
        tuple[dict, list[Det3DDataSample]]: ``inputs`` with ``imgs``
        Shape (B, N, 3, H, W) and ``points`` (list of Shape (P_i, 5)), and
        the data samples with ``gt_occ``, ``gt_depth``, ``mask_camera`` and
        the camera metainfo.
    """
    from mmdet3d.structures import Det3DDataSample

    gen = torch.Generator().manual_seed(seed)
    cam2img, lidar2cam = ring_camera_rig(num_cams, img_shape, focal)
    img_aug = torch.eye(4, dtype=torch.float64).repeat(num_cams, 1, 1)
    lidar2img = img_aug @ cam2img @ lidar2cam
    lo = torch.tensor(pc_range[:3], dtype=torch.float64)
    hi = torch.tensor(pc_range[3:], dtype=torch.float64)
    imgs = torch.randn(batch_size, num_cams, 3, *img_shape, generator=gen)
    points, samples = [], []
    for b in range(batch_size):
        count = num_points[b % len(num_points)]
        xyz = lo + (hi - lo) * torch.rand(count, 3, generator=gen,
                                          dtype=torch.float64)
        extra = torch.rand(count, 2, generator=gen, dtype=torch.float64)
        pts = torch.cat([xyz, extra], dim=1).float()
        points.append(pts)
        gt_occ = torch.randint(0, num_classes, tuple(occ_shape),
                               generator=gen)
        gt_occ[torch.rand(tuple(occ_shape), generator=gen) < 0.05] = 255
        sample = Det3DDataSample(
            metainfo=dict(
                sample_idx=b,
                img_shape=tuple(img_shape),
                cam2img=cam2img.float().numpy(),
                lidar2cam=lidar2cam.float().numpy(),
                img_aug_matrix=img_aug.float().numpy(),
                lidar2img=lidar2img.float().numpy(),
                bda_matrix=torch.eye(4).numpy()))
        sample.gt_occ = gt_occ
        sample.mask_camera = torch.rand(tuple(occ_shape), generator=gen) < 0.8
        sample.gt_depth = sparse_depth_maps(pts, lidar2img, img_shape)
        samples.append(sample)
    return dict(imgs=imgs, points=points), samples


def make_temporal_scene(num_key_frames: int = 3,
                        step: float = 2.0,
                        **batch_kwargs) -> List[Tuple[dict, List]]:
    """A scene of key frames in the two-frame layout of
    ``LoadPreviousKeyFrames`` (T = 2), for the temporal models.

    Key frame ``k`` is :func:`make_occ_batch` with ``seed=k``, its sample
    ``b`` has the token ``f'frame{k}-{b}'``; the ego drives ``step``
    metres along +x per key frame, so ``prev2curr`` is a translation by
    ``-step`` (the identity for the first frame, which repeats itself as
    its previous frame).

    Args:
        num_key_frames (int): Key frames. Defaults to 3.
        step (float): Ego motion per key frame, metres. Defaults to 2.
        **batch_kwargs: For :func:`make_occ_batch` (not ``seed``).

    Returns:
        list[tuple[dict, list[Det3DDataSample]]]: Per key frame, inputs
        with ``imgs`` Shape (B, 2 * N, 3, H, W) (current views first) and
        the samples with the ``prev_*`` metainfo.
    """
    frames = [make_occ_batch(seed=k, **batch_kwargs)
              for k in range(num_key_frames)]
    scene = []
    for k, (inputs, samples) in enumerate(frames):
        p_inputs, p_samples = frames[max(k - 1, 0)]
        prev2curr = np.eye(4, dtype=np.float32)
        prev2curr[0, 3] = -step if k else 0.0
        inputs = dict(inputs, imgs=torch.cat([inputs['imgs'],
                                              p_inputs['imgs']], 1))
        for b, (sample, prev) in enumerate(zip(samples, p_samples)):
            meta = prev.metainfo
            sample.set_metainfo(dict(
                token=f'frame{k}-{b}',
                prev_tokens=[f'frame{max(k - 1, 0)}-{b}'],
                prev2curr=prev2curr[None],
                prev_cam2img=meta['cam2img'][None],
                prev_lidar2cam=meta['lidar2cam'][None],
                prev_img_aug_matrix=meta['img_aug_matrix'][None],
                prev_lidar2img=meta['lidar2img'][None],
                prev_points=[p_inputs['points'][b].numpy()]))
        scene.append((inputs, samples))
    return scene
