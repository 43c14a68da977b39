"""Sparse to dense: full 3D volumes and bird's-eye-view (BEV) maps.

Pure tensor scatters, the same for both backends and differentiable. BEV
maps are ``(B, C, Y, X)``: dim -1 indexes x and dim -2 indexes y, as in
mmdet3d's BEV feature maps.
"""
from typing import Sequence

import torch
from torch import Tensor

from ..layers.cell_max import cell_max
from .sparse_tensor import SparseTensor

BEV_REDUCTIONS = ('concat', 'max', 'mean', 'sum')


def to_dense(x: SparseTensor) -> Tensor:
    """Scatter a sparse tensor into a dense, channels-first volume.

    Inactive sites are zero; equals spconv's ``SparseConvTensor.dense()``.

    Args:
        x (SparseTensor): Features of shape (N, C).

    Returns:
        Tensor: Shape (B, C, Z, Y, X).
    """
    size_z, size_y, size_x = x.spatial_shape
    dense = x.features.new_zeros(x.batch_size, size_z, size_y, size_x,
                                 x.num_channels)
    coords = x.coords.long()
    dense = dense.index_put(
        (coords[:, 0], coords[:, 1], coords[:, 2], coords[:, 3]), x.features)
    return dense.permute(0, 4, 1, 2, 3).contiguous()


def scatter_bev(features: Tensor, batch: Tensor, cell_y: Tensor,
                cell_x: Tensor, batch_size: int, bev_shape: Sequence[int],
                reduce: str = 'max') -> Tensor:
    """Pool row features into BEV cells.

    Args:
        features (Tensor): Shape (N, C).
        batch (Tensor): Sample of each row. Shape (N,).
        cell_y (Tensor): BEV row (y index) of each row, in [0, H). Shape (N,).
        cell_x (Tensor): BEV column (x index), in [0, W). Shape (N,).
        batch_size (int): B.
        bev_shape (Sequence[int]): ``(H, W)`` = (y cells, x cells).
        reduce (str): ``'max'``, ``'mean'`` or ``'sum'`` over the rows of a
            cell; empty cells are 0. Defaults to ``'max'``.

    Returns:
        Tensor: Shape (B, C, H, W).
    """
    height, width = (int(s) for s in bev_shape)
    channels = features.shape[1]
    cells = (batch.long() * height + cell_y.long()) * width + cell_x.long()
    num_cells = batch_size * height * width
    if reduce == 'max':
        # Empty cells 0; ties share the gradient (cell_max).
        flat = cell_max(features, cells, num_cells)
    elif reduce in ('mean', 'sum'):
        flat = features.new_zeros(num_cells, channels).index_add(
            0, cells, features)
        if reduce == 'mean':
            counts = torch.bincount(cells, minlength=flat.shape[0])
            flat = flat / counts.clamp(min=1).to(flat.dtype)[:, None]
    else:
        raise ValueError("scatter_bev reduce must be 'max', 'mean' or "
                         f"'sum', got {reduce!r}")
    return flat.view(batch_size, height, width,
                     channels).permute(0, 3, 1, 2).contiguous()


def to_dense_bev(x: SparseTensor, reduce: str = 'concat') -> Tensor:
    """Collapse the z axis of a sparse tensor into a BEV map.

    ``'concat'`` keeps the height: channel ``c * Z + z`` holds feature ``c``
    of level ``z``, as mmdet3d's ``SparseEncoder`` flattens its output.
    The other reductions pool the column.

    Args:
        x (SparseTensor): Features of shape (N, C) on a (Z, Y, X) grid.
        reduce (str): One of ``'concat'``, ``'max'``, ``'mean'``,
            ``'sum'``. Defaults to ``'concat'``.

    Returns:
        Tensor: Shape (B, C * Z, Y, X) for ``'concat'``, else (B, C, Y, X).
    """
    if reduce not in BEV_REDUCTIONS:
        raise ValueError(
            f'to_dense_bev reduce must be one of {BEV_REDUCTIONS}, got '
            f'{reduce!r}')
    size_z, size_y, size_x = x.spatial_shape
    if reduce == 'concat':
        dense = to_dense(x)
        return dense.view(x.batch_size, x.num_channels * size_z, size_y,
                          size_x)
    coords = x.coords.long()
    return scatter_bev(x.features, coords[:, 0], coords[:, 2], coords[:, 3],
                       x.batch_size, (size_y, size_x), reduce)
