"""Camera geometry shared by the depth-lifting models.

Conventions (those of mmdet3d 1.x ``lidar2img``):

* Pixel coordinates are continuous and pixel ``i`` covers ``[i, i + 1)`` (as
  in the depth maps of ``projects.occ_common.transforms``), so a stride-``s``
  feature cell ``j`` is centred on ``(j + 0.5) * s``.
* Points live in the *working frame* of
  :mod:`projects.occ_common.transforms.frames` (the LiDAR frame, or the ego
  frame after ``PointsToEgoFrame`` for Occ3D), called "lidar" in the matrix
  names as in mmdet3d.
* All matrices are homogeneous 4x4. ``cam2img`` is the padded intrinsic
  matrix, ``lidar2cam`` the extrinsic and ``img_aug_matrix`` the image
  augmentation; the full projection ``img_aug @ cam2img @ lidar2cam`` maps a
  working-frame point ``(x, y, z, 1)`` to ``(u * d, v * d, d, 1)`` where
  ``(u, v)`` is the augmented pixel and ``d`` the depth along the optical
  axis. Lifting a pixel at depth ``d`` back to 3D inverts this same matrix,
  so projection and lifting can never disagree.
* Depth bins and point projection are those of
  :mod:`projects.occ_common.geometry.depth` (BEVDepth's bins, lifted at
  their near edge ``min + k * step``), shared with the depth loss and the
  depth-map transforms.
"""
import functools
from typing import Sequence, Tuple

import torch
from torch import Tensor

from ...geometry.depth import depth_bin_values, normalize_depth_bound
from ...geometry.inverse import invert_matrix
from ...utils.precision import float32_math
from .cylindrical_coords import cartesian_to_cylindrical


def create_frustum(img_shape: Sequence[int], feat_shape: Sequence[int],
                   depth_bound: Sequence[float]) -> Tensor:
    """Augmented-image pixel and depth of every feature cell and depth bin.

    Args:
        img_shape (Sequence[int]): Network input ``(H, W)``.
        feat_shape (Sequence[int]): Feature map ``(h, w)``.
        depth_bound (Sequence[float]): ``(min, max, step)`` in metres.

    Returns:
        Tensor: ``(u, v, d)`` per bin and cell. Shape (D, h, w, 3).
    """
    img_h, img_w = int(img_shape[0]), int(img_shape[1])
    feat_h, feat_w = int(feat_shape[0]), int(feat_shape[1])
    if min(img_h, img_w, feat_h, feat_w) <= 0:
        raise ValueError('create_frustum needs positive sizes, got image '
                         f'{tuple(img_shape)} and features '
                         f'{tuple(feat_shape)}')
    depths = depth_bin_values(depth_bound)
    # Cell centres in pixel units; the stride may differ per axis when the
    # image size is not a multiple of the feature size.
    us = (torch.arange(feat_w) + 0.5) * (img_w / feat_w)
    vs = (torch.arange(feat_h) + 0.5) * (img_h / feat_h)
    d, v, u = torch.meshgrid(depths, vs, us, indexing='ij')
    return torch.stack([u, v, d], dim=-1)


@functools.lru_cache(maxsize=16)
def _device_frustum(img_shape: Tuple[int, int], feat_shape: Tuple[int, int],
                    depth_bound: Tuple[float, ...],
                    device: torch.device) -> Tensor:
    frustum = create_frustum(img_shape, feat_shape, depth_bound).to(device)
    # Shared between calls: a write would change every later lift.
    frustum.requires_grad_(False)
    return frustum


def device_frustum(img_shape: Sequence[int], feat_shape: Sequence[int],
                   depth_bound: Sequence[float],
                   device: torch.device) -> Tensor:
    """:func:`create_frustum` on ``device``, made once per geometry.

    The frustum depends only on the sizes and the bins, so a model that
    lifts every batch need not rebuild it on the host and copy it to the
    GPU each time (a host-to-device copy per call). The tensor is shared
    between callers: read it, never write it. Under ``torch.compile`` the
    cache is bypassed and the frustum is built in the graph: Dynamo traced
    through the cache anyway, with a warning per compiled model.

    Returns:
        Tensor: float32. Shape (D, h, w, 3).
    """
    build = (_device_frustum.__wrapped__
             if torch.compiler.is_compiling() else _device_frustum)
    return build(
        tuple(int(v) for v in img_shape), tuple(int(v) for v in feat_shape),
        normalize_depth_bound(depth_bound), torch.device(device))


@float32_math
def lidar2img_matrix(cam2img: Tensor, lidar2cam: Tensor,
                     img_aug_matrix: Tensor) -> Tensor:
    """Full projection ``img_aug @ cam2img @ lidar2cam``.

    Args:
        cam2img (Tensor): Intrinsics. Shape (..., 4, 4).
        lidar2cam (Tensor): Extrinsics. Shape (..., 4, 4).
        img_aug_matrix (Tensor): Image augmentation. Shape (..., 4, 4).

    Returns:
        Tensor: Projection. Shape (..., 4, 4).
    """
    for name, mat in (('cam2img', cam2img), ('lidar2cam', lidar2cam),
                      ('img_aug_matrix', img_aug_matrix)):
        if mat.shape[-2:] != (4, 4):
            raise ValueError(f'{name} must be (..., 4, 4), got '
                             f'{tuple(mat.shape)}')
    return img_aug_matrix @ cam2img @ lidar2cam


@float32_math
def frustum_to_lidar(frustum: Tensor, lidar2img: Tensor) -> Tensor:
    """Lift every frustum point ``(u, v, d)`` into the working frame.

    Args:
        frustum (Tensor): From :func:`create_frustum`. Shape (D, h, w, 3).
        lidar2img (Tensor): Full projections. Shape (B, N, 4, 4).

    Returns:
        Tensor: Working-frame points. Shape (B, N, D, h, w, 3).
    """
    if lidar2img.dim() != 4 or lidar2img.shape[-2:] != (4, 4):
        raise ValueError('lidar2img must be (B, N, 4, 4), got '
                         f'{tuple(lidar2img.shape)}')
    frustum = frustum.to(lidar2img)
    u, v, d = frustum.unbind(-1)
    homo = torch.stack([u * d, v * d, d, torch.ones_like(d)], dim=-1)
    # Inverting in float64 keeps the far (50 m) bins accurate; closed form
    # in an exported graph (invert_matrix).
    img2lidar = invert_matrix(lidar2img.double()).to(lidar2img.dtype)
    pts = torch.einsum('bnij,dhwj->bndhwi', img2lidar, homo)
    return pts[..., :3]


#: Channels of :func:`cylindrical_position_embedding` per depth bin.
POSITION_EMBED_DIMS = 4


@float32_math
def cylindrical_position_embedding(points: Tensor,
                                   cyl_range: Sequence[float]) -> Tensor:
    """Cylindrical coordinates of the frustum: ``V_coord`` (eq. 5).

    Each bin's working-frame point becomes ``(r', sin theta, cos theta,
    z')`` with ``r'`` and ``z'`` scaled to ``[0, 1]`` by the cylinder range
    (values outside the range go beyond ``[0, 1]`` unchanged so the network
    still sees them). The azimuth is encoded by its sine and cosine rather
    than scaled: ``(theta + pi) / 2 pi`` jumps from 1 to 0 across
    ``theta = +-pi``, the car's left side in the nuScenes LiDAR frame, so
    neighbouring feature columns of CAM_BACK_LEFT would differ by 1.0. The
    paper does not say how it encodes theta; sine and cosine are continuous
    and, as a pair, still identify the angle. The ``D`` bins are stacked on
    channels, as in PETR's 3D position embedding.

    Args:
        points (Tensor): From :func:`frustum_to_lidar`.
            Shape (B, N, D, h, w, 3).
        cyl_range (Sequence[float]): ``(r_min, theta_min, z_min, r_max,
            theta_max, z_max)``; the azimuth range is not used.

    Returns:
        Tensor: Embedding. Shape (B * N, D * 4, h, w), channel ``4 * k + i``
        holding ``(r', sin theta, cos theta, z')[i]`` of bin ``k``.
    """
    if points.dim() != 6 or points.shape[-1] != 3:
        raise ValueError('points must be (B, N, D, h, w, 3), got '
                         f'{tuple(points.shape)}')
    if len(cyl_range) != 6:
        raise ValueError(f'cyl_range must have 6 values, got {cyl_range}')
    if any(float(h) <= float(low)
           for low, h in zip(cyl_range[:3], cyl_range[3:])):
        raise ValueError(f'cyl_range needs max > min per axis: {cyl_range}')
    lo = points.new_tensor(cyl_range[:3])
    hi = points.new_tensor(cyl_range[3:])
    r, theta, z = cartesian_to_cylindrical(points).unbind(-1)
    emb = torch.stack([(r - lo[0]) / (hi[0] - lo[0]),
                       torch.sin(theta),
                       torch.cos(theta), (z - lo[2]) / (hi[2] - lo[2])],
                      dim=-1)
    b, n, d, h, w, c = emb.shape
    return emb.permute(0, 1, 2, 5, 3, 4).reshape(b * n, d * c, h, w)


@float32_math
def camera_parameter_vector(cam2img: Tensor, lidar2cam: Tensor,
                            img_aug_matrix: Tensor) -> Tensor:
    """Per-camera parameters for BEVDepth's camera-aware depth prediction.

    Concatenates ``fx, fy, cx, cy``, the 2x2 image-augmentation block and its
    pixel translation, and the 3x4 camera-to-LiDAR transform.

    Args:
        cam2img (Tensor): Intrinsics. Shape (B, N, 4, 4).
        lidar2cam (Tensor): Extrinsics. Shape (B, N, 4, 4).
        img_aug_matrix (Tensor): Image augmentation. Shape (B, N, 4, 4).

    Returns:
        Tensor: Parameters. Shape (B, N, 22).
    """
    intr = torch.stack([
        cam2img[..., 0, 0], cam2img[..., 1, 1], cam2img[..., 0, 2],
        cam2img[..., 1, 2]
    ],
                       dim=-1)
    aug_rot = img_aug_matrix[..., :2, :2].flatten(-2)
    # The pixel shift sits in column 2 (it multiplies the depth) under the
    # projective convention; column 3 is added for matrices that use it.
    aug_trans = img_aug_matrix[..., :2, 2] + img_aug_matrix[..., :2, 3]
    cam2lidar = invert_matrix(lidar2cam.double()).to(lidar2cam.dtype)
    return torch.cat(
        [intr, aug_rot, aug_trans, cam2lidar[..., :3, :].flatten(-2)],
        dim=-1)
