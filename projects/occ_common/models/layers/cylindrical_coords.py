"""Cartesian <-> cylindrical coordinate conversion.

OccCylindrical (eqs. 4-5) and PointOcc describe every point by its radius
``r``, azimuth ``theta`` and height ``z`` in the working frame (the LiDAR
frame, or the ego frame for Occ3D; see
:mod:`projects.occ_common.transforms.frames`). The conversion
lives here rather than in ``projects/occ_cyl`` because the shared
:class:`DepthNet` position embedding needs it too.
"""
import torch
from torch import Tensor

from ...utils.precision import float32_math


@float32_math
def cartesian_to_cylindrical(xyz: Tensor) -> Tensor:
    """Convert Cartesian ``(x, y, z)`` to cylindrical ``(r, theta, z)``.

    ``theta = atan2(y, x)`` lies in ``[-pi, pi]``; the origin maps to
    ``r = 0, theta = 0``.

    Args:
        xyz (Tensor): Points. Shape (..., 3).

    Returns:
        Tensor: ``(r, theta, z)``. Shape (..., 3).
    """
    if xyz.shape[-1] != 3:
        raise ValueError('cartesian_to_cylindrical expects (..., 3) '
                         f'points, got shape {tuple(xyz.shape)}')
    x, y, z = xyz.unbind(-1)
    # hypot is exact where sqrt(x**2 + y**2) overflows or loses precision.
    r = torch.hypot(x, y)
    theta = torch.atan2(y, x)
    return torch.stack([r, theta, z], dim=-1)


@float32_math
def cylindrical_to_cartesian(rtz: Tensor) -> Tensor:
    """Convert cylindrical ``(r, theta, z)`` to Cartesian ``(x, y, z)``.

    Args:
        rtz (Tensor): Points. Shape (..., 3).

    Returns:
        Tensor: ``(x, y, z)``. Shape (..., 3).
    """
    if rtz.shape[-1] != 3:
        raise ValueError('cylindrical_to_cartesian expects (..., 3) '
                         f'points, got shape {tuple(rtz.shape)}')
    r, theta, z = rtz.unbind(-1)
    return torch.stack([r * torch.cos(theta), r * torch.sin(theta), z],
                       dim=-1)
