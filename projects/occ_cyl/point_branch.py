"""LiDAR point branch with image-feature sampling (OccCylindrical eqs. 2-4).
"""
from typing import List, Sequence

import torch
import torch.nn.functional as F
from mmcv.cnn import build_norm_layer
from mmdet3d.registry import MODELS
from mmdet3d.utils import ConfigType, OptMultiConfig
from mmengine.model import BaseModule
from torch import Tensor, nn

from projects.occ_common.geometry.depth import project_points
from projects.occ_common.models.layers import cartesian_to_cylindrical
from projects.occ_common.models.sparse.sparse_norm_act import batch_norm_rows


def _mlp(channels: Sequence[int], norm_cfg: ConfigType) -> nn.Sequential:
    """Shared per-point MLP: Linear-Norm-ReLU for every layer."""
    layers = []
    for c_in, c_out in zip(channels[:-1], channels[1:]):
        layers += [
            nn.Linear(c_in, c_out, bias=False),
            build_norm_layer(norm_cfg, c_out)[1],
            nn.ReLU(inplace=True)
        ]
    return nn.Sequential(*layers)


def run_mlp(mlp: nn.Sequential, x: Tensor) -> Tensor:
    """Apply a point MLP, tolerating a single point in training.

    ``nn.BatchNorm1d`` raises in training on one row (a batch whose only
    LiDAR point survived the filters); :func:`batch_norm_rows` normalises
    such a batch with the running statistics instead, as the sparse
    encoders do.

    Args:
        mlp (nn.Sequential): The MLP of :func:`_mlp`.
        x (Tensor): Shape (P, C_in).

    Returns:
        Tensor: Shape (P, C_out).
    """
    for layer in mlp:
        x = batch_norm_rows(layer, x) if isinstance(
            layer, nn.BatchNorm1d) else layer(x)
    return x


def sample_image_features(xyz: Tensor,
                          feats: Tensor,
                          lidar2img: Tensor,
                          input_shape: Sequence[int],
                          img_shape: Sequence[int],
                          min_depth: float = 0.1) -> Tensor:
    """Bilinearly sample multi-view features at each point's projection.

    A point is visible in a camera when it lies at least ``min_depth`` in
    front of it and projects inside the augmented image (``img_shape``,
    before padding). Its feature is the mean over the cameras that see it
    and zero when none does (eq. 3 of OccCylindrical).

    Args:
        xyz (Tensor): Working-frame points. Shape (P, 3).
        feats (Tensor): Feature maps of the sample's cameras, covering the
            padded network input. Shape (N, C, h, w).
        lidar2img (Tensor): Full projections. Shape (N, 4, 4).
        input_shape (Sequence[int]): Padded network input ``(H_in, W_in)``.
        img_shape (Sequence[int]): Augmented image ``(H, W)`` before
            padding.
        min_depth (float): Closest visible depth in metres. Defaults to 0.1.

    Returns:
        Tensor: Sampled features. Shape (P, C).
    """
    num_cams, channels = feats.shape[:2]
    if lidar2img.shape != (num_cams, 4, 4):
        raise ValueError(f'lidar2img must be ({num_cams}, 4, 4) for '
                         f'{num_cams} feature maps, got '
                         f'{tuple(lidar2img.shape)}')
    if xyz.shape[0] == 0:
        return feats.new_zeros(0, channels)
    uv, depth = project_points(xyz, lidar2img)
    img_h, img_w = float(img_shape[0]), float(img_shape[1])
    # Pixel i covers [i, i + 1), so the image spans [0, W) x [0, H) and
    # grid_sample's -1 (align_corners=False) is the left edge u = 0.
    visible = (depth >= min_depth) & (uv[..., 0] >= 0) & \
        (uv[..., 0] < img_w) & (uv[..., 1] >= 0) & (uv[..., 1] < img_h)
    # Only the visible (camera, point) pairs are sampled: a nuScenes point
    # is seen by 0.44 cameras on average, so sampling every point in every
    # camera (and masking) did ~2.3x the work and held (N, P, C) buffers.
    # Sorted by camera, then point: each camera's pairs are one slice.
    cam, point = visible.nonzero(as_tuple=True)
    in_h, in_w = float(input_shape[0]), float(input_shape[1])
    grid = torch.stack(
        [uv[cam, point, 0] / in_w * 2 - 1, uv[cam, point, 1] / in_h * 2 - 1],
        dim=-1).to(torch.promote_types(uv.dtype, feats.dtype))
    sums = feats.new_zeros(xyz.shape[0], channels)
    if point.numel() == 0:
        # Nothing visible: zeros that stay connected to ``feats``, as the
        # sampled features are when something is.
        return sums + feats.sum() * 0
    pieces = grid.split(visible.sum(dim=1).tolist())
    sampled = torch.cat([
        F.grid_sample(
            feats[n:n + 1], cam_grid.view(1, 1, -1, 2),
            align_corners=False)[0, :, 0].t()
        for n, cam_grid in enumerate(pieces) if cam_grid.shape[0] > 0
    ])  # (K, C), K visible pairs
    # Camera by camera, as the sum over cameras it replaces.
    # (grid_sample returns float32 under CPU autocast and for a float32
    # grid under CUDA's, whatever the features' dtype.)
    sums.index_add_(0, point, sampled.to(sums.dtype))
    count = visible.sum(dim=0).clamp(min=1).to(feats.dtype)
    return sums / count.unsqueeze(1)


@MODELS.register_module()
class LidarPointBranch(BaseModule):
    """Per-point features from geometry and the camera context.

    Implements eqs. 2-4 of OccCylindrical: an MLP encodes each point's raw
    attributes (plus its radius and azimuth), the point is projected into
    every camera's ``V_context`` and bilinearly sampled there
    (:func:`sample_image_features`), and a second MLP fuses the two. The
    caller converts the points to cylindrical coordinates for the voxel
    partition.

    Args:
        in_channels (int): Attributes per point, e.g. 5 for
            ``(x, y, z, intensity, time lag)``.
        img_channels (int): Channels of ``V_context``.
        geo_channels (Sequence[int]): Widths of the geometric MLP.
            Defaults to (64, 64).
        out_channels (Sequence[int]): Widths of the fusion MLP; the last is
            the point feature size. Defaults to (64, 64).
        with_cylindrical_input (bool): Append ``(r, theta)`` to the raw
            attributes. Defaults to True.
        with_image_features (bool): Sample ``V_context``; False gives a
            LiDAR-only branch. Defaults to True.
        input_norm (bool): Normalise the raw attributes (one ``norm_cfg``
            layer, the first of ``geo_mlp``), as the point encoders of
            Cylinder3D and PointOcc (the paper's ref. [18]) do: x, y in
            tens of metres, intensity in 0-255 and the angle in radians
            otherwise enter the first layer at scales 100x apart. The paper
            does not say. Defaults to False.
        norm_cfg (dict): Normalisation of the MLPs. Defaults to BN1d.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 in_channels: int,
                 img_channels: int,
                 geo_channels: Sequence[int] = (64, 64),
                 out_channels: Sequence[int] = (64, 64),
                 with_cylindrical_input: bool = True,
                 with_image_features: bool = True,
                 input_norm: bool = False,
                 norm_cfg: ConfigType = dict(type='BN1d'),
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(init_cfg=init_cfg)
        if in_channels < 3:
            raise ValueError('LidarPointBranch: points need at least x, y, '
                             f'z, got in_channels={in_channels}')
        self.in_channels = in_channels
        self.with_cylindrical_input = with_cylindrical_input
        self.with_image_features = with_image_features
        geo_in = in_channels + (2 if with_cylindrical_input else 0)
        # The input norm leads the geometric MLP, so that run_mlp's
        # one-point handling covers it too.
        self.geo_mlp = _mlp([geo_in, *geo_channels], norm_cfg)
        if input_norm:
            self.geo_mlp.insert(0, build_norm_layer(norm_cfg, geo_in)[1])
        fuse_in = geo_channels[-1] + (
            img_channels if with_image_features else 0)
        self.fuse_mlp = _mlp([fuse_in, *out_channels], norm_cfg)
        self.out_channels = out_channels[-1]

    def forward(self, points: List[Tensor], context: Tensor,
                lidar2img: Tensor, input_shape: Sequence[int],
                img_shapes: Sequence[Sequence[int]]) -> List[Tensor]:
        """Encode every sample's points.

        Args:
            points (list[Tensor]): Per sample. Shape (P_i, in_channels).
            context (Tensor): ``V_context``. Shape (B, N, C, h, w).
            lidar2img (Tensor): Full projections. Shape (B, N, 4, 4).
            input_shape (Sequence[int]): Padded network input
                ``(H_in, W_in)``.
            img_shapes (Sequence[Sequence[int]]): Per sample, the augmented
                image ``(H, W)`` before padding.

        Returns:
            list[Tensor]: Per sample. Shape (P_i, out_channels).
        """
        if len(points) != context.shape[0]:
            raise ValueError(f'LidarPointBranch: {len(points)} point clouds'
                             f' for a batch of {context.shape[0]}')
        for i, pts in enumerate(points):
            if pts.dim() != 2 or pts.shape[1] != self.in_channels:
                raise ValueError(
                    f'LidarPointBranch: sample {i} has points of shape '
                    f'{tuple(pts.shape)}, expected (P, {self.in_channels})')
        counts = [p.shape[0] for p in points]
        # One MLP call over the whole batch keeps BatchNorm statistics
        # batch-wide, as for any other layer. Coordinates keep at least
        # their own precision: under --amp the context is float16 /
        # bfloat16, which would move a point at 50 m by up to 0.25 m.
        dtype = torch.promote_types(points[0].dtype, context.dtype)
        pts = torch.cat(points, dim=0).to(dtype)
        if pts.shape[0] == 0:
            # BatchNorm cannot run on zero rows; the empty result stays
            # connected to the weights so backward still works.
            empty = context.sum() * 0 + sum(
                p.sum() for p in self.parameters()) * 0
            return [empty.expand(0, self.out_channels) for _ in points]
        geo_in = pts
        if self.with_cylindrical_input:
            cyl = cartesian_to_cylindrical(pts[:, :3])
            geo_in = torch.cat([pts, cyl[:, :2]], dim=1)
        fused = [run_mlp(self.geo_mlp, geo_in)]
        if self.with_image_features:
            img_feats = [
                sample_image_features(xyz[:, :3].to(dtype),
                                      context[i], lidar2img[i], input_shape,
                                      img_shapes[i])
                for i, xyz in enumerate(points)
            ]
            fused.append(torch.cat(img_feats, dim=0))
        out = run_mlp(self.fuse_mlp, torch.cat(fused, dim=1))
        return list(out.split(counts, dim=0))
