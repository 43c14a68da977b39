"""Bidirectional linear incremental discretization: virtual points.

Implements the discretization step of SDG-OCC's view transformation (Duan
et al., CVPR 2025, Sec. 3.4 and Table 4): a pixel with an extended depth d
spawns a few virtual points around d, each weighted by the predicted depth
distribution at its depth, so that only a few points per pixel are lifted
instead of all D depth bins.

The paper gives no formula, only the names r ("range of bilinear growth
discretization", 1 m) and l ("diffusion feature layers", 8). Read here as
*bidirectional linear increments*: starting at d, l steps of r / l outwards
in both directions, i.e. the 2 l + 1 depths ``d + k r / l`` for
k = -l .. l, which span [d - r, d + r] and include d. Why: "bidirectional
incremental" describes growth from d both ways; the authors' released
config writes the setting as ``diffusion = [0.0, 1.0, 8]`` (offsets from 0
to r = 1 m in l = 8 steps); and Table 4's "depth precision" is then the
step r / l (r = 2, l = 4 gives 0.5 m, the LSS bin width: the paper's
"lower depth precision").

Weights (not given by the paper either): the distribution interpolated
linearly between the bin depths at each virtual depth, then rescaled so
that a pixel's virtual points together carry the mass of its whole depth
distribution (1 for a softmax) -- the mass an LSS pixel lifts over its D
bins. Without that rescaling a pixel's total weight would depend on r and l
(about 0.0-0.65 at r = 2, l = 4 and 1.7-1.85 at r = 1, l = 8 against 1.0
for an LSS pixel), so Table 4 would vary the feature scale, not the depth
precision.

Depth-bin convention: that of :mod:`projects.occ_common.geometry.depth`
(BEVDepth): ``depth_bound = (dmin, dmax, step)`` gives
D = round((dmax - dmin) / step) bins, lifted at ``dmin + k * step``.
"""
from typing import Sequence, Tuple

import torch
from torch import Tensor

from projects.occ_common.geometry.depth import (depth_bin_coordinate,
                                                num_depth_bins)
from projects.occ_common.utils.precision import float32_math


def virtual_point_offsets(radius: float, num_layers: int,
                          device=None, dtype=None) -> Tensor:
    """Offsets ``k r / l`` (k = -l .. l) of the virtual points from d.

    Args:
        radius (float): Range r, metres, >= 0.
        num_layers (int): Layers l per direction, >= 1.
        device (torch.device, optional): Device of the result.
        dtype (torch.dtype, optional): Dtype of the result.

    Returns:
        Tensor: Increasing offsets, metres. Shape (2 l + 1,).
    """
    if num_layers < 1:
        raise ValueError(f'num_layers must be >= 1, got {num_layers}')
    if radius < 0:
        raise ValueError(f'radius must be >= 0, got {radius}')
    steps = torch.arange(
        -num_layers, num_layers + 1, device=device, dtype=dtype)
    return steps * (radius / num_layers)


@float32_math
def virtual_point_depths(ext_depth: Tensor, radius: float,
                         num_layers: int) -> Tensor:
    """Depths of the virtual points spawned by each pixel.

    Args:
        ext_depth (Tensor): Extended depth, 0 where none. Shape (M, H, W).
        radius (float): Range r, metres.
        num_layers (int): Layers l per direction.

    Returns:
        Tensor: ``d + k r / l`` for k = -l .. l (not masked; see
        :func:`bilinear_incremental_discretization` for validity).
        Shape (M, 2 l + 1, H, W).
    """
    offsets = virtual_point_offsets(radius, num_layers, ext_depth.device,
                                    ext_depth.dtype)
    return ext_depth.unsqueeze(1) + offsets.view(1, -1, 1, 1)


@float32_math
def interpolate_depth_prob(depth_prob: Tensor, depths: Tensor,
                           depth_bound: Sequence[float]) -> Tensor:
    """Linearly interpolate a per-pixel depth distribution at given depths.

    With u = :func:`depth_bin_coordinate` (``(depth - dmin) / step`` for
    uniform bins) clamped to [0, D - 1], k = floor(u) and
    t = u - k, the value is ``(1 - t) * p[k] + t * p[k + 1]``. A depth
    before the first bin or past the last one takes that end bin's value:
    the distribution says nothing beyond its range, and the LiDAR depth
    that placed the point is kept (see
    :func:`bilinear_incremental_discretization`).

    Args:
        depth_prob (Tensor): Depth distribution over D bins.
            Shape (M, D, H, W).
        depths (Tensor): Query depths per pixel. Shape (M, L, H, W).
        depth_bound (Sequence[float]): (dmin, dmax, step).

    Returns:
        Tensor: Values, differentiable w.r.t. depth_prob.
        Shape (M, L, H, W).
    """
    num_bins = num_depth_bins(depth_bound)
    if depth_prob.dim() != 4 or depth_prob.shape[1] != num_bins:
        raise ValueError(f'depth_prob must have shape (M, {num_bins}, H, W) '
                         f'for depth_bound {tuple(depth_bound)}, got '
                         f'{tuple(depth_prob.shape)}')
    if (depths.dim() != 4 or depths.shape[0] != depth_prob.shape[0]
            or depths.shape[2:] != depth_prob.shape[2:]):
        raise ValueError('depths must have shape (M, L, H, W) = '
                         f'({depth_prob.shape[0]}, L, '
                         f'{depth_prob.shape[2]}, {depth_prob.shape[3]}), '
                         f'got {tuple(depths.shape)}')
    pos = depth_bin_coordinate(depths.clamp(min=1e-6),
                               depth_bound).clamp(0, num_bins - 1)
    lower = pos.floor()
    frac = pos - lower
    lower = lower.long()
    upper = (lower + 1).clamp(max=num_bins - 1)
    p_lower = torch.gather(depth_prob, 1, lower)
    p_upper = torch.gather(depth_prob, 1, upper)
    return (1 - frac) * p_lower + frac * p_upper


@float32_math
def bilinear_incremental_discretization(
        ext_depth: Tensor, depth_prob: Tensor, depth_bound: Sequence[float],
        radius: float, num_layers: int) -> Tuple[Tensor, Tensor, Tensor]:
    """Virtual points of every pixel with an extended depth.

    A virtual point is valid when its pixel has an extended depth d > 0 and
    its own depth is positive (in front of the camera); the point at d
    itself always is. Its weight is the interpolated distribution
    (:func:`interpolate_depth_prob`) rescaled per pixel so that the valid
    points' weights sum to the pixel's distribution mass ``sum_k p[k]``
    (uniform over the valid points if the interpolated values sum to 0).

    Pixels whose d lies beyond the last bin (or before the first) are not
    dropped: all their virtual points read the end bin's probability, so
    after the rescaling they share the pixel's mass evenly and lift its
    feature at the LiDAR depth; the distribution then gets no gradient from
    them (it has no bin there to prefer).

    Args:
        ext_depth (Tensor): Extended depth from semantic diffusion, 0 where
            none. Shape (M, H, W).
        depth_prob (Tensor): Predicted depth distribution.
            Shape (M, D, H, W).
        depth_bound (Sequence[float]): (dmin, dmax, step).
        radius (float): Range r, metres (1 m in the paper).
        num_layers (int): Layers l per direction (8 in the paper).

    Returns:
        tuple[Tensor, Tensor, Tensor]: ``depths`` (M, 2 l + 1, H, W),
        ``weights`` (same shape; 0 where invalid) and ``valid`` (same
        shape, bool).
    """
    if ext_depth.dim() != 3:
        raise ValueError('ext_depth must have shape (M, H, W), got '
                         f'{tuple(ext_depth.shape)}')
    depths = virtual_point_depths(ext_depth, radius, num_layers)
    raw = interpolate_depth_prob(depth_prob, depths, depth_bound)
    valid = (depths > 0) & (ext_depth > 0).unsqueeze(1)
    raw = raw * valid.to(raw.dtype)
    mass = depth_prob.sum(dim=1, keepdim=True)
    total = raw.sum(dim=1, keepdim=True)
    count = valid.sum(dim=1, keepdim=True).clamp(min=1).to(raw.dtype)
    uniform = valid.to(raw.dtype) / count
    share = torch.where(total > 0, raw / total.clamp(min=1e-12), uniform)
    return depths, share * mass, valid
