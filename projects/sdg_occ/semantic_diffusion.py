"""Semantic depth diffusion of sparse LiDAR depth maps.

Implements the semantic diffusion step of SDG-OCC's view transformation
(Duan et al., CVPR 2025, Sec. 3.4, eqs. 1-2 and Fig. 4): a pixel with a
foreground class borrows the mean depth of the LiDAR returns of the same
class around it, so that the sparse LiDAR depth spreads along objects but
never across a semantic boundary.
"""
import math

import torch
from torch import Tensor


def _disc_offsets(radius: float):
    """Integer pixel offsets (dp, dq) with dp**2 + dq**2 <= radius**2."""
    reach = int(math.floor(radius))
    limit = radius * radius
    return [(dp, dq) for dp in range(-reach, reach + 1)
            for dq in range(-reach, reach + 1) if dp * dp + dq * dq <= limit]


def semantic_depth_diffusion(depth: Tensor, seg: Tensor,
                             radius: float) -> Tensor:
    """Diffuse sparse LiDAR depth inside semantic regions.

    For every pixel (i, j) whose class ``seg[n, i, j]`` is not 0 the result
    is the mean depth of the LiDAR pixels (p, q) of the same image with
    ``depth > 0``, the same class and ``(p - i)**2 + (q - j)**2 <=
    radius**2``. Pixels that hold a LiDAR return keep their own depth (the
    co-point replaces the mean, whatever its class); every other pixel,
    including background pixels (class 0) without a return and foreground
    pixels with no same-class return in reach, is 0.

    The loop runs over the offsets of the radius disc (O(radius**2) tensor
    operations on whole maps), never over pixels.

    Args:
        depth (Tensor): Sparse depth, 0 where there is no LiDAR return.
            Shape (N, H, W).
        seg (Tensor): Integer class map, 0 is background. Shape (N, H, W).
        radius (float): Diffusion radius in pixels of these maps, >= 0.

    Returns:
        Tensor: Extended depth, 0 where no depth could be assigned.
        Shape (N, H, W).
    """
    if depth.dim() != 3:
        raise ValueError('semantic_depth_diffusion expects depth of shape '
                         f'(N, H, W), got {tuple(depth.shape)}')
    if seg.shape != depth.shape:
        raise ValueError('semantic_depth_diffusion expects seg of the same '
                         f'shape as depth {tuple(depth.shape)}, got '
                         f'{tuple(seg.shape)}')
    if seg.is_floating_point() or seg.dtype == torch.bool:
        raise ValueError('semantic_depth_diffusion expects an integer class '
                         f'map, got dtype {seg.dtype}')
    if not depth.is_floating_point():
        raise ValueError('semantic_depth_diffusion expects a floating point '
                         f'depth map, got dtype {depth.dtype}')
    if not (math.isfinite(radius) and radius >= 0):
        raise ValueError('semantic_depth_diffusion expects a finite radius '
                         f'>= 0, got {radius}')

    _, height, width = depth.shape
    reach = int(math.floor(radius))
    has_return = depth > 0
    # Padding with depth 0 makes out-of-image neighbours count as "no
    # return", so they never enter a sum.
    pad = (reach, reach, reach, reach)
    depth_pad = torch.nn.functional.pad(
        torch.where(has_return, depth, torch.zeros_like(depth)), pad)
    seg_pad = torch.nn.functional.pad(seg, pad)

    total = torch.zeros_like(depth)
    count = torch.zeros_like(depth)
    for dp, dq in _disc_offsets(radius):
        rows = slice(reach + dp, reach + dp + height)
        cols = slice(reach + dq, reach + dq + width)
        nb_depth = depth_pad[:, rows, cols]
        hit = (nb_depth > 0) & (seg_pad[:, rows, cols] == seg)
        total = total + torch.where(hit, nb_depth, torch.zeros_like(depth))
        count = count + hit.to(depth.dtype)

    mean = total / count.clamp(min=1)
    diffused = torch.where((seg != 0) & (count > 0), mean,
                           torch.zeros_like(depth))
    return torch.where(has_return, depth, diffused)
