"""Align a previous frame's BEV feature map with the current ego frame.

Temporal BEV fusion (BEVDet4D, FlashOcc-4D, the T-frame input of SDG-OCC
Sec. 3.1) concatenates the BEV of earlier frames with the current one; a
static object must then sit in the same cell in every frame, so each
earlier BEV is resampled into the current frame with the ego motion, as
BEVDet4D's ``shift_feature`` does with ``grid_sample``.

Conventions (those of :mod:`projects.sdg_occ.bev_pool`): a BEV is
``(B, C, Y, X)`` over ``point_cloud_range``, cell ``(iy, ix)`` covering
``[xmin + ix * sx, xmin + (ix + 1) * sx)`` in x and likewise in y, so its
centre is at ``xmin + (ix + 0.5) * sx``. ``prev2curr`` maps a point of the
previous working frame (column vector ``(x, y, z, 1)``) to the current one.
"""
from typing import Sequence

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from ..utils.precision import float32_math


def relative_pose(prev_lidar2global: np.ndarray,
                  curr_lidar2global: np.ndarray,
                  bda: np.ndarray = None) -> np.ndarray:
    """The 4x4 map from the previous working frame to the current one.

    ``curr_lidar2global^-1 @ prev_lidar2global`` takes a static point from
    the previous frame through the world into the current frame. With a
    BEV augmentation ``bda`` applied to every frame of a sample (as
    BEVDet4D draws one for all its frames), the working frames are the
    augmented ones, so the map is conjugated: ``bda @ rel @ bda^-1``.

    Args:
        prev_lidar2global (np.ndarray): Previous working frame to global
            (``ego2global @ lidar2ego``). Shape (4, 4).
        curr_lidar2global (np.ndarray): Current working frame to global.
            Shape (4, 4).
        bda (np.ndarray, optional): The BEV augmentation of the sample.
            Shape (4, 4). Defaults to the identity.

    Returns:
        np.ndarray: ``prev2curr``, float64. Shape (4, 4).
    """
    prev = np.asarray(prev_lidar2global, dtype=np.float64)
    curr = np.asarray(curr_lidar2global, dtype=np.float64)
    for name, mat in (('prev_lidar2global', prev),
                      ('curr_lidar2global', curr)):
        if mat.shape != (4, 4):
            raise ValueError(f'relative_pose: {name} must be 4x4, got '
                             f'{mat.shape}')
    rel = np.linalg.inv(curr) @ prev
    if bda is not None:
        bda = np.asarray(bda, dtype=np.float64)
        rel = bda @ rel @ np.linalg.inv(bda)
    return rel


@float32_math
def warp_bev(prev_bev: Tensor, prev2curr: Tensor,
             point_cloud_range: Sequence[float],
             mode: str = 'bilinear') -> Tensor:
    """Resample a previous frame's BEV onto the current frame's grid.

    Each current cell centre ``p`` reads the previous BEV at
    ``prev2curr^-1 @ p`` (only the planar part: x, y and the yaw; z is
    ignored, a BEV has no height). Cells whose source lies outside the
    previous grid get zeros, the value of an empty pooled BEV cell.

    Args:
        prev_bev (Tensor): Shape (B, C, Y, X).
        prev2curr (Tensor): Previous to current working frame, e.g. from
            :func:`relative_pose`. Shape (B, 4, 4).
        point_cloud_range (Sequence[float]): (xmin, ymin, zmin, xmax, ymax,
            zmax) of both grids, metres.
        mode (str): ``grid_sample`` interpolation, ``'bilinear'`` (as
            BEVDet4D) or ``'nearest'``. Defaults to 'bilinear'.

    Returns:
        Tensor: The previous BEV in the current frame. Shape (B, C, Y, X).
    """
    if prev_bev.dim() != 4:
        raise ValueError('warp_bev: prev_bev must be (B, C, Y, X), got '
                         f'{tuple(prev_bev.shape)}')
    batch, _, num_y, num_x = prev_bev.shape
    if tuple(prev2curr.shape) != (batch, 4, 4):
        raise ValueError(f'warp_bev: prev2curr must be ({batch}, 4, 4), '
                         f'got {tuple(prev2curr.shape)}')
    if len(point_cloud_range) != 6:
        raise ValueError('warp_bev: point_cloud_range must be (xmin, ymin, '
                         f'zmin, xmax, ymax, zmax), got {point_cloud_range}')
    xmin, ymin, _, xmax, ymax, _ = (float(v) for v in point_cloud_range)
    # Pose algebra in float64: a float32 inverse of a pose kilometres from
    # the origin would move features by centimetres.
    curr2prev = torch.linalg.inv(prev2curr.double())
    device = prev_bev.device
    size_x, size_y = (xmax - xmin) / num_x, (ymax - ymin) / num_y
    xs = xmin + (torch.arange(num_x, device=device, dtype=torch.float64)
                 + 0.5) * size_x
    ys = ymin + (torch.arange(num_y, device=device, dtype=torch.float64)
                 + 0.5) * size_y
    grid_y, grid_x = torch.meshgrid(ys, xs, indexing='ij')
    centres = torch.stack([grid_x, grid_y], -1).reshape(-1, 2)  # (YX, 2)
    rot = curr2prev[:, :2, :2]  # (B, 2, 2)
    shift = curr2prev[:, :2, 3]  # (B, 2)
    src = centres @ rot.transpose(1, 2) + shift[:, None]  # (B, YX, 2)
    # grid_sample with align_corners=False puts -1 and 1 on the outer
    # edges of the border cells, i.e. at xmin and xmax.
    norm = torch.stack([(src[..., 0] - xmin) / (xmax - xmin),
                        (src[..., 1] - ymin) / (ymax - ymin)], -1) * 2 - 1
    norm = norm.reshape(batch, num_y, num_x, 2).to(prev_bev.dtype)
    return F.grid_sample(
        prev_bev, norm, mode=mode, padding_mode='zeros', align_corners=False)
