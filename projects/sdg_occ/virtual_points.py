"""Bilinear incremental discretization: virtual points around a depth.

Implements eq. 2 of SDG-OCC (Duan et al., CVPR 2025, Sec. 3.2, Table 4):
a pixel with an extended depth d spawns ``num_layers`` virtual points at
depths evenly spaced over [d - r, d + r], and each virtual point is weighted
by the predicted depth distribution linearly interpolated at its depth, so
that only a few points per pixel are lifted instead of all D depth bins.

Depth-bin convention: that of :mod:`projects.occ_common.geometry.depth`
(BEVDepth): ``depth_bound = (dmin, dmax, step)`` gives
D = round((dmax - dmin) / step) bins, lifted at ``dmin + k * step``. The
interpolation nodes are these same depths, so a virtual point that falls on
a bin depth gets exactly the weight the plain LSS lift gives that bin.
"""
from typing import Sequence, Tuple

import torch
from torch import Tensor

from projects.occ_common.geometry.depth import num_depth_bins


def virtual_point_depths(ext_depth: Tensor, radius: float,
                         num_layers: int) -> Tensor:
    """Depths of the virtual points spawned by each pixel.

    Args:
        ext_depth (Tensor): Extended depth, 0 where none. Shape (M, H, W).
        radius (float): Half width r of the depth interval, metres.
        num_layers (int): Number L of virtual points per pixel; with L = 1
            the single point sits at d itself.

    Returns:
        Tensor: ``d - r + 2 r l / (L - 1)`` for l = 0 .. L - 1 (not masked;
        see :func:`interpolate_depth_prob` for validity).
        Shape (M, L, H, W).
    """
    if num_layers < 1:
        raise ValueError(f'num_layers must be >= 1, got {num_layers}')
    if radius < 0:
        raise ValueError(f'radius must be >= 0, got {radius}')
    if num_layers == 1:
        offsets = ext_depth.new_zeros(1)
    else:
        offsets = torch.linspace(
            -radius, radius, num_layers, device=ext_depth.device,
            dtype=ext_depth.dtype)
    return ext_depth.unsqueeze(1) + offsets.view(1, -1, 1, 1)


def interpolate_depth_prob(depth_prob: Tensor, depths: Tensor,
                           depth_bound: Sequence[float]
                           ) -> Tuple[Tensor, Tensor]:
    """Linearly interpolate a per-pixel depth distribution at given depths.

    With u = (depth - dmin) / step, k = floor(u) and t = u - k, the weight is
    ``(1 - t) * p[k] + t * p[k + 1]``; a depth outside [dmin, dmin + (D - 1)
    * step] gets weight 0 and is marked invalid.

    Args:
        depth_prob (Tensor): Depth distribution over D bins.
            Shape (M, D, H, W).
        depths (Tensor): Query depths per pixel. Shape (M, L, H, W).
        depth_bound (Sequence[float]): (dmin, dmax, step).

    Returns:
        tuple[Tensor, Tensor]: Weights (differentiable w.r.t. depth_prob),
        shape (M, L, H, W), and the validity mask, bool, same shape.
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
    dmin, _, step = (float(v) for v in depth_bound)
    pos = (depths - dmin) / step
    valid = (pos >= 0) & (pos <= num_bins - 1)
    lower = pos.floor().clamp(0, num_bins - 1)
    frac = (pos - lower).clamp(0, 1)
    lower = lower.long()
    upper = (lower + 1).clamp(max=num_bins - 1)
    p_lower = torch.gather(depth_prob, 1, lower)
    p_upper = torch.gather(depth_prob, 1, upper)
    weights = (1 - frac) * p_lower + frac * p_upper
    return weights * valid.to(weights.dtype), valid


def bilinear_incremental_discretization(
        ext_depth: Tensor, depth_prob: Tensor, depth_bound: Sequence[float],
        radius: float, num_layers: int) -> Tuple[Tensor, Tensor, Tensor]:
    """Virtual points of every pixel with an extended depth (eq. 2).

    Args:
        ext_depth (Tensor): Extended depth from semantic diffusion, 0 where
            none. Shape (M, H, W).
        depth_prob (Tensor): Predicted depth distribution.
            Shape (M, D, H, W).
        depth_bound (Sequence[float]): (dmin, dmax, step).
        radius (float): Half width r of the depth interval, metres (1 m in
            the paper).
        num_layers (int): Virtual points per pixel (8 in the paper).

    Returns:
        tuple[Tensor, Tensor, Tensor]: ``depths`` (M, L, H, W), ``weights``
        (M, L, H, W) and ``valid`` (M, L, H, W) bool, true where the pixel
        has an extended depth and the virtual depth lies inside the bins.
    """
    if ext_depth.dim() != 3:
        raise ValueError('ext_depth must have shape (M, H, W), got '
                         f'{tuple(ext_depth.shape)}')
    depths = virtual_point_depths(ext_depth, radius, num_layers)
    weights, valid = interpolate_depth_prob(depth_prob, depths, depth_bound)
    valid = valid & (ext_depth > 0).unsqueeze(1)
    return depths, weights * valid.to(weights.dtype), valid
