"""Slow, obviously correct references of the point <-> voxel transfers.

The optimised paths (:func:`~projects.occ_common.models.sparse.
trilinear_plan`, the ``SPVCNNEncoder`` forward) look voxels up through
sorted keys, share lookups between points and fold BatchNorm at
inference; these references use a dense grid and one plain formula, so
tests can check the optimised paths against them on tiny grids (outputs
and gradients).
"""
import itertools

import torch
import torch.nn.functional as F
from torch import Tensor

from projects.occ_common.models.sparse import (SparseTensor, delinearize,
                                               linearize, point_voxel_offsets,
                                               scatter_mean, voxel_rows)


def dense_trilinear_devoxelize(x: SparseTensor, batch: Tensor,
                               position: Tensor) -> Tensor:
    """Trilinear interpolation read off a dense, zero-padded grid.

    Corner ``base + c`` of a point at ``u`` (``base = floor(u - 0.5)``)
    has weight ``prod_d (1 - |u_d - 0.5 - corner_d|)`` if it is an active
    voxel and 0 otherwise; the result is the weighted mean over the eight
    corners (0 where no corner is active).

    Args:
        x (SparseTensor): Voxel features. Shape (N, C).
        batch (Tensor): Sample of each point. Shape (P,).
        position (Tensor): ``(z, y, x)`` in grid units. Shape (P, 3).

    Returns:
        Tensor: Shape (P, C); differentiable in ``x.features``.
    """
    size = torch.tensor(x.spatial_shape)
    coords = x.coords.long()
    # One cell of padding on every side; corners farther out read it too.
    dense = x.features.new_zeros(x.batch_size, *(size + 2).tolist(),
                                 x.num_channels)
    active = torch.zeros(dense.shape[:-1], dtype=torch.bool)
    index = (coords[:, 0], *(coords[:, 1:] + 1).unbind(1))
    dense = dense.index_put(index, x.features)
    active[index] = True
    base = torch.floor(position - 0.5).long()
    total = x.features.new_zeros(position.shape[0], x.num_channels)
    norm = x.features.new_zeros(position.shape[0], 1)
    for corner in itertools.product((0, 1), repeat=3):
        cell = base + torch.tensor(corner)
        weight = (1 - (position - 0.5 - cell).abs()).prod(dim=1)
        on_grid = ((cell >= 0) & (cell < size)).all(dim=1)
        cell = torch.minimum((cell + 1).clamp(min=0), size + 1)
        index = (batch.long(), *cell.unbind(1))
        weight = weight * (active[index] & on_grid)
        total = total + weight[:, None] * dense[index]
        norm = norm + weight[:, None]
    return total / norm.clamp(min=1e-12)


def reference_spvcnn_forward(encoder, points) -> Tensor:
    """``SPVCNNEncoder``'s layers applied point by point, as first written.

    Every point looks up its corners (:func:`dense_trilinear_devoxelize`)
    and its voxel (``voxel_rows``) at every stage, and the point MLPs run
    unfolded (Linear, BatchNorm, ReLU) in either mode; the BEV projection
    is the encoder's own.

    Args:
        encoder (SPVCNNEncoder): The encoder whose layers are used.
        points (Sequence[Tensor]): Per sample, Shape (N_i, C).

    Returns:
        Tensor: The BEV map. Shape (B, out_channels, H, W).
    """
    def mlp(layer, feats):
        return F.relu(layer.norm(layer.linear(feats)))

    batch, position, features, _ = encoder._gather_points(points)
    upper = position.new_tensor(encoder.sparse_shape).long() - 1
    fine = torch.minimum(torch.floor(position).long(), upper)
    keys, rows = torch.unique(
        linearize(batch, fine, encoder.sparse_shape), return_inverse=True)
    if encoder.point_offsets:
        offsets = point_voxel_offsets(features[:, :3], rows, keys.numel(),
                                      fine, encoder.voxel_size,
                                      encoder.point_cloud_range[:3])
        first, second = encoder.point_input
        features = second(mlp(first, torch.cat([features, offsets], 1)))
    x = SparseTensor(scatter_mean(features, rows, keys.numel()),
                     delinearize(keys, encoder.sparse_shape),
                     encoder.sparse_shape, len(points))
    x = encoder.stem(x)
    point_feats = dense_trilinear_devoxelize(x, batch, position)
    stride = 1
    for stage, layer, stage_stride in zip(encoder.stages, encoder.point_mlps,
                                          encoder.stage_strides):
        x = stage(x)
        stride *= stage_stride
        point_feats = dense_trilinear_devoxelize(
            x, batch, position / stride) + mlp(layer, point_feats)
        stage_rows = voxel_rows(x, batch, torch.div(
            fine, stride, rounding_mode='floor'))
        x = x.replace_feature(x.features + scatter_mean(
            point_feats, stage_rows, x.num_voxels))
    return encoder._to_bev(x)
