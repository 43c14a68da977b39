"""Semantic- and depth-guided (SDG) view transformation.

Implements Sec. 3.4 of SDG-OCC (Duan et al., CVPR 2025), eqs. 1-2 and
Fig. 4: the key-frame LiDAR points are projected into every camera as a
sparse depth map at feature resolution; semantic diffusion (eqs. 1-2)
spreads their depth inside the predicted semantic regions; every pixel
with an extended depth spawns a few virtual points around it (bidirectional
linear incremental discretization) weighted by its predicted depth
distribution; the remaining pixels fall back to the plain LSS lift over
all depth bins. The features of all lifted points are pooled into the
camera BEV.
"""
from typing import Dict, List, Optional, Sequence

import torch
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import Tensor

from projects.occ_common.geometry.depth import (nearest_depth_map,
                                                normalize_depth_bound,
                                                num_depth_bins)
from projects.occ_common.geometry.inverse import invert_matrix
from projects.occ_common.models.layers.camera_geometry import (
    device_frustum, frustum_to_lidar)
from projects.occ_common.utils.device_path import accelerator_path
from .bev_pool import (BEVPoolIndexCache, BEVPoolIndices, bev_pool,
                       bev_pool_indices, bev_pool_mask)
from .semantic_diffusion import semantic_depth_diffusion
from .virtual_points import bilinear_incremental_discretization

_FALLBACKS = ('lss', 'none')


def key_frame_masks(points: Sequence[Tensor],
                    time_dims: Optional[Sequence[Optional[int]]] = None
                    ) -> List[Optional[Tensor]]:
    """Which points of every sample are key-frame points (time lag 0).

    Merged sweeps smear moving objects (a car now at 20 m whose return
    0.45 s earlier was 4.5 m nearer), so the guidance depth maps use the
    key frame only, as the depth supervision does (``PointsToDepthMaps``)
    and as the authors' released config does (one sweep). The rule is that
    of ``PointsToDepthMaps``: without a time column every point is a
    key-frame point.

    Args:
        points (Sequence[Tensor]): Per sample, Shape (P_b, C).
        time_dims (Sequence[int | None], optional): Per sample, the column
            of the time lag (``points_time_dim`` of
            ``LoadOccPointsFromMultiSweeps``), None where no sweeps were
            merged. Defaults to None (no sample has one).

    Returns:
        list[Tensor | None]: Per sample, a bool mask (P_b,), or None where
        every point is a key-frame point.
    """
    if time_dims is None:
        return [None] * len(points)
    if len(time_dims) != len(points):
        raise ValueError(f'key_frame_points got {len(time_dims)} time '
                         f'columns for {len(points)} point clouds')
    masks = []
    for b, (pts, dim) in enumerate(zip(points, time_dims)):
        if dim is not None and not 0 <= dim < pts.shape[1]:
            raise ValueError(f'points of sample {b} have {pts.shape[1]} '
                             f'columns, no time column {dim}')
        masks.append(None if dim is None else pts[:, dim] == 0)
    return masks


def key_frame_points(points: Sequence[Tensor],
                     time_dims: Optional[Sequence[Optional[int]]] = None
                     ) -> List[Tensor]:
    """The key-frame points of every sample (:func:`key_frame_masks`).

    Args:
        points (Sequence[Tensor]): Per sample, Shape (P_b, C).
        time_dims (Sequence[int | None], optional): As for
            :func:`key_frame_masks`. Defaults to None.

    Returns:
        list[Tensor]: Per sample, the rows with time lag 0.
    """
    return [
        pts if mask is None else pts[mask]
        for pts, mask in zip(points, key_frame_masks(points, time_dims))
    ]


def points_to_depth_maps(
        points: Sequence[Tensor],
        lidar2img: Tensor,
        img_shape: Sequence[int],
        feat_shape: Sequence[int],
        time_dims: Optional[Sequence[Optional[int]]] = None) -> Tensor:
    """Nearest LiDAR depth of every feature cell of every camera.

    :func:`~projects.occ_common.geometry.depth.nearest_depth_map` at
    feature resolution, per sample: a point projected to pixel (u, v) falls
    in cell ``(floor(v / s_y), floor(u / s_x))`` with the strides
    ``s = img / feat``, and the cell keeps its nearest return, the surface
    the camera sees.

    Args:
        points (Sequence[Tensor]): Per sample, (x, y, z, ...) in the working
            frame. Shape (P_b, C >= 3).
        lidar2img (Tensor): Working frame to augmented pixels, as
            ``(u d, v d, d, 1)``. Shape (B, N, 4, 4).
        img_shape (Sequence[int]): Network input (H, W).
        feat_shape (Sequence[int]): Feature map (h, w).
        time_dims (Sequence[int | None], optional): Per sample, the time
            column; only key-frame points are projected
            (:func:`key_frame_masks`). Defaults to None (all points).

    Returns:
        Tensor: Depth, 0 where no return. Shape (B * N, h, w).
    """
    if len(points) != lidar2img.shape[0]:
        raise ValueError(f'points_to_depth_maps got {len(points)} point '
                         f'clouds for a batch of {lidar2img.shape[0]} '
                         'camera sets')
    maps = []
    for b, pts in enumerate(points):
        if pts.dim() != 2 or pts.shape[1] < 3:
            raise ValueError(f'points of sample {b} must be (P, C >= 3), '
                             f'got {tuple(pts.shape)}')
    for b, mask in enumerate(key_frame_masks(points, time_dims)):
        maps.append(
            nearest_depth_map(
                points[b], lidar2img[b], img_shape, feat_shape,
                point_mask=mask))
    return torch.cat(maps, dim=0)


@MODELS.register_module()
class SDGViewTransform(BaseModule):
    """SDG view transformation from image features to the camera BEV.

    Args:
        point_cloud_range (Sequence[float]): (xmin, ymin, zmin, xmax, ymax,
            zmax) of the BEV, metres.
        bev_shape (Sequence[int]): (Y, X) cells of the camera BEV.
        depth_bound (Sequence[float]): (dmin, dmax, step) of the depth bins.
        diffusion_radius (float): Radius, in feature-map pixels, of the
            semantic diffusion. Defaults to 2.0.
        layer_radius (float): Range r, metres, of the virtual points: they
            span [d - r, d + r] (1 m in the paper, Table 4). Defaults to
            1.0.
        num_layers (int): Layers l per direction: 2 l + 1 virtual points
            per pixel, r / l apart (8 in the paper; see
            :mod:`.virtual_points` for this reading). Defaults to 8.
        fallback (str): Lift of pixels without an extended depth: ``'lss'``
            (all bins, weighted by the depth distribution) or ``'none'``
            (dropped). Defaults to 'lss'.
        use_sdg (bool): False lifts every pixel with plain LSS (the
            baseline of Table 3). Defaults to True.
        init_cfg (dict, optional): mmengine initialisation config.
    """

    def __init__(self,
                 point_cloud_range: Sequence[float],
                 bev_shape: Sequence[int],
                 depth_bound: Sequence[float],
                 diffusion_radius: float = 2.0,
                 layer_radius: float = 1.0,
                 num_layers: int = 8,
                 fallback: str = 'lss',
                 use_sdg: bool = True,
                 init_cfg: Optional[dict] = None):
        super().__init__(init_cfg=init_cfg)
        if fallback not in _FALLBACKS:
            raise ValueError(f'SDGViewTransform fallback must be one of '
                             f'{_FALLBACKS}, got {fallback!r}')
        if not use_sdg and fallback != 'lss':
            raise ValueError('SDGViewTransform(use_sdg=False) lifts every '
                             "pixel with LSS and needs fallback='lss'")
        self.point_cloud_range = tuple(float(v) for v in point_cloud_range)
        self.bev_shape = tuple(int(v) for v in bev_shape)
        self.depth_bound = normalize_depth_bound(depth_bound)
        self.num_bins = num_depth_bins(self.depth_bound)
        self.diffusion_radius = float(diffusion_radius)
        self.layer_radius = float(layer_radius)
        self.num_layers = int(num_layers)
        self.fallback = fallback
        self.use_sdg = use_sdg
        self.lss_cache = BEVPoolIndexCache()

    def _lss_indices(self, lidar2img: Tensor, img_shape: Sequence[int],
                     feat_shape: Sequence[int]) -> BEVPoolIndices:
        """Indices of the dense LSS frustum, cached per geometry.

        Frustum point (m, k, i, j) has weight index ``((m * D + k) * h + i)
        * w + j`` (the flat order of the depth distribution) and feature
        index ``(m * h + i) * w + j``.
        """
        batch, num_cams = lidar2img.shape[:2]
        feat_h, feat_w = (int(v) for v in feat_shape)

        def compute() -> BEVPoolIndices:
            frustum = device_frustum(img_shape, feat_shape,
                                     self.depth_bound, lidar2img.device)
            coords = frustum_to_lidar(frustum, lidar2img).reshape(-1, 3)
            device = lidar2img.device
            cam = torch.arange(batch * num_cams, device=device)
            pix = torch.arange(feat_h * feat_w, device=device)
            feat_index = (cam.view(-1, 1, 1) * (feat_h * feat_w) +
                          pix.view(1, 1, -1)).expand(-1, self.num_bins,
                                                     -1).reshape(-1)
            batch_index = (cam // num_cams).view(-1, 1).expand(
                -1, self.num_bins * feat_h * feat_w).reshape(-1)
            return bev_pool_indices(coords, batch_index, feat_index, batch,
                                    self.point_cloud_range, self.bev_shape)

        if accelerator_path(lidar2img):
            # Comparing the geometry with the cached one reads a device
            # value (torch.equal, a sync); the indices cost a few dozen
            # launches and no sync to recompute.
            return compute()
        key = (lidar2img, tuple(int(v) for v in img_shape), (feat_h, feat_w))
        return self.lss_cache.get(key, compute)

    def _sdg_indices(self, depths: Tensor, valid: Tensor, lidar2img: Tensor,
                     img_shape: Sequence[int]) -> BEVPoolIndices:
        """Indices of the valid virtual points (depths (M, L, h, w))."""
        num_m, num_l, feat_h, feat_w = depths.shape
        batch, num_cams = lidar2img.shape[:2]
        if accelerator_path(depths):
            # Every virtual point, the invalid ones dropped by the pooling
            # (no host read of their count).
            flat = torch.arange(valid.numel(), device=valid.device)
            keep = valid.reshape(-1)
        else:
            flat = torch.nonzero(valid.reshape(-1),
                                 as_tuple=False).squeeze(1)
            keep = None
        pix = flat % (feat_h * feat_w)
        cam = flat // (num_l * feat_h * feat_w)
        row, col = pix // feat_w, pix % feat_w
        # Same cell centres as the LSS frustum (create_frustum).
        u = (col.to(depths.dtype) + 0.5) * (img_shape[1] / feat_w)
        v = (row.to(depths.dtype) + 0.5) * (img_shape[0] / feat_h)
        d = depths.reshape(-1)[flat]
        homo = torch.stack([u * d, v * d, d, torch.ones_like(d)], dim=1)
        img2lidar = invert_matrix(lidar2img.double()).to(depths.dtype)
        coords = torch.einsum('pij,pj->pi',
                              img2lidar.reshape(-1, 4, 4)[cam], homo)[:, :3]
        return bev_pool_indices(
            coords,
            cam // num_cams,
            cam * (feat_h * feat_w) + pix,
            batch,
            self.point_cloud_range,
            self.bev_shape,
            weight_index=flat,
            valid=keep)

    def forward(self, context: Tensor, depth_prob: Tensor,
                seg_logits: Optional[Tensor],
                points: Optional[Sequence[Tensor]],
                lidar2img: Tensor,
                img_shape: Sequence[int],
                points_time_dims: Optional[Sequence[Optional[int]]] = None
                ) -> Dict[str, Tensor]:
        """Lift image features into the camera BEV.

        Args:
            context (Tensor): Texture features. Shape (B * N, C, h, w).
            depth_prob (Tensor): Depth distribution. Shape (B * N, D, h, w).
            seg_logits (Tensor, optional): Semantic logits; their argmax is
                the class map of the diffusion (class 0 is background).
                Required when ``use_sdg``. Shape (B * N, S, h, w).
            points (Sequence[Tensor], optional): Per sample LiDAR points in
                the working frame; only the key frame guides the lift (see
                :func:`key_frame_points`). Required when ``use_sdg``.
                Shape (P_b, C >= 3).
            lidar2img (Tensor): Working frame to augmented pixels.
                Shape (B, N, 4, 4).
            img_shape (Sequence[int]): Network input (H, W).
            points_time_dims (Sequence[int | None], optional): Per sample,
                the time-lag column of ``points`` (None: no merged sweeps).
                Defaults to None.

        Returns:
            dict[str, Tensor]: ``bev`` (B, C, Y, X); ``bev_mask`` (B, 1, Y,
            X) bool, cells that received a point; with ``use_sdg``
            ``sparse_depth`` (B * N, h, w), the key-frame LiDAR depth, and
            ``ext_depth``, the diffused depth, same shape;
            ``num_sdg_points`` and ``num_lss_points``, long scalars, points
            pooled by each lift.
        """
        batch, num_cams = lidar2img.shape[:2]
        num_m, _, feat_h, feat_w = context.shape
        if num_m != batch * num_cams or depth_prob.shape != (
                num_m, self.num_bins, feat_h, feat_w):
            raise ValueError(
                'SDGViewTransform expects context (B*N, C, h, w) and '
                f'depth_prob (B*N, {self.num_bins}, h, w) for B*N = '
                f'{batch * num_cams}, got {tuple(context.shape)} and '
                f'{tuple(depth_prob.shape)}')
        feats = context.permute(0, 2, 3, 1).reshape(-1, context.shape[1])
        indices: List[BEVPoolIndices] = []
        weights: List[Tensor] = []
        zero = torch.zeros((), dtype=torch.long, device=context.device)
        out = dict(num_sdg_points=zero, num_lss_points=zero)

        has_ext = torch.zeros(
            num_m, feat_h, feat_w, dtype=torch.bool, device=context.device)
        if self.use_sdg:
            if seg_logits is None or seg_logits.shape[0] != num_m \
                    or seg_logits.shape[2:] != context.shape[2:]:
                got = None if seg_logits is None else tuple(seg_logits.shape)
                raise ValueError('SDGViewTransform(use_sdg=True) needs '
                                 f'seg_logits of shape ({num_m}, S, {feat_h}'
                                 f', {feat_w}), got {got}')
            if points is None:
                raise ValueError('SDGViewTransform(use_sdg=True) is guided '
                                 'by LiDAR depth and needs the points')
            with torch.no_grad():
                sparse = points_to_depth_maps(
                    points, lidar2img.float(), img_shape, (feat_h, feat_w),
                    points_time_dims)
                ext_depth = semantic_depth_diffusion(
                    sparse, seg_logits.argmax(dim=1), self.diffusion_radius)
            has_ext = ext_depth > 0
            out.update(sparse_depth=sparse, ext_depth=ext_depth)
            depths, vp_weights, valid = bilinear_incremental_discretization(
                ext_depth.to(depth_prob.dtype), depth_prob, self.depth_bound,
                self.layer_radius, self.num_layers)
            sdg = self._sdg_indices(depths, valid, lidar2img, img_shape)
            indices.append(sdg)
            weights.append(vp_weights.reshape(-1))
            out['num_sdg_points'] = sdg.num_pooled()

        if self.fallback == 'lss':
            lss = self._lss_indices(lidar2img, img_shape, (feat_h, feat_w))
            lss = lss.select(~has_ext.reshape(-1)[lss.feat_index])
            indices.append(lss)
            weights.append(depth_prob.reshape(-1))
            out['num_lss_points'] = lss.num_pooled()

        bev = context.new_zeros(batch, context.shape[1], *self.bev_shape)
        mask = torch.zeros(
            batch, 1, *self.bev_shape, dtype=torch.bool,
            device=context.device)
        for index, weight in zip(indices, weights):
            bev = bev + bev_pool(feats, weight, index)
            mask = mask | bev_pool_mask(index)
        out.update(bev=bev, bev_mask=mask)
        return out
