"""Vectorised, differentiable BEV pooling with precomputed indices.

The camera BEV of a lift-splat view transform is a sum over lifted points
of ``weight * feature`` scattered into BEV cells. As in BEVPoolv2 (BEVDet),
the outer product of features and weights is never materialised as a
frustum tensor: every kept point is described by three indices (its weight,
its feature vector and its BEV cell), computed once per geometry, and
pooling is one gather and one ``index_add_``. Pure PyTorch, so it runs
(and back-propagates into features and weights) on CPU and CUDA.

BEV orientation matches ``SPVCNNEncoder``: cell index
``floor((coord - range_min) / cell)``, the last dimension is x and the one
before it is y; heights are collapsed (summed) over [zmin, zmax).
"""
from typing import Callable, NamedTuple, Optional, Sequence, Tuple

import torch
from torch import Tensor

from projects.occ_common.utils.device_path import accelerator_path


class BEVPoolIndices(NamedTuple):
    """Indices of the points that land inside the BEV grid.

    Attributes:
        weight_index (Tensor): Index of each kept point into the flat weight
            vector. Shape (P,).
        feat_index (Tensor): Index of each kept point into the rows of the
            feature matrix. Shape (P,).
        bev_index (Tensor): Flat cell index ``b * Y * X + y * X + x``, or
            the drop cell ``B * Y * X`` for a point that is not pooled.
            The CPU's path keeps only pooled points, sorted ascending so
            that a cell's points are contiguous (the layout a segment-sum
            kernel needs); the GPUs' keeps every point in its input order
            and marks the dropped ones, because compacting would read the
            kept count on the host (a sync). Shape (P,).
        batch_size (int): Number B of BEV maps.
        bev_shape (tuple[int, int]): (Y, X).
    """
    weight_index: Tensor
    feat_index: Tensor
    bev_index: Tensor
    batch_size: int
    bev_shape: Tuple[int, int]

    @property
    def drop_cell(self) -> int:
        """int: ``B * Y * X``, the cell of the points not pooled."""
        return self.batch_size * self.bev_shape[0] * self.bev_shape[1]

    def select(self, keep: Tensor) -> 'BEVPoolIndices':
        """Indices restricted to the points where ``keep`` (P,) is true.

        The CPU's path drops the other points; the GPUs' moves them to the
        drop cell (no sync).
        """
        if accelerator_path(keep):
            return self._replace(bev_index=torch.where(
                keep, self.bev_index,
                torch.full_like(self.bev_index, self.drop_cell)))
        return BEVPoolIndices(self.weight_index[keep], self.feat_index[keep],
                              self.bev_index[keep], self.batch_size,
                              self.bev_shape)

    def num_pooled(self) -> Tensor:
        """Number of pooled points, a long scalar on the indices' device
        (no host read)."""
        return (self.bev_index < self.drop_cell).sum()


def bev_cell_size(point_cloud_range: Sequence[float],
                  bev_shape: Sequence[int]) -> Tuple[float, float]:
    """Cell size (x, y) in metres of a (Y, X) grid over the range."""
    if len(point_cloud_range) != 6:
        raise ValueError('point_cloud_range must be (xmin, ymin, zmin, xmax, '
                         f'ymax, zmax), got {tuple(point_cloud_range)}')
    if len(bev_shape) != 2 or min(bev_shape) < 1:
        raise ValueError(f'bev_shape must be (Y, X) >= 1, got {bev_shape}')
    xmin, ymin, _, xmax, ymax, _ = (float(v) for v in point_cloud_range)
    return (xmax - xmin) / bev_shape[1], (ymax - ymin) / bev_shape[0]


def bev_pool_indices(coords: Tensor, batch_index: Tensor,
                     feat_index: Tensor, batch_size: int,
                     point_cloud_range: Sequence[float],
                     bev_shape: Sequence[int],
                     weight_index: Optional[Tensor] = None,
                     valid: Optional[Tensor] = None) -> BEVPoolIndices:
    """Compute the pooling indices of a set of lifted points.

    Args:
        coords (Tensor): Point coordinates (x, y, z), metres. Shape (P, 3).
        batch_index (Tensor): Sample of each point. Shape (P,).
        feat_index (Tensor): Feature row of each point. Shape (P,).
        batch_size (int): Number B of samples.
        point_cloud_range (Sequence[float]): (xmin, ymin, zmin, xmax, ymax,
            zmax); points outside are dropped.
        bev_shape (Sequence[int]): (Y, X).
        weight_index (Tensor, optional): Weight of each point; defaults to
            the point's position 0 .. P - 1. Shape (P,).
        valid (Tensor, optional): bool, False drops the point whatever its
            position. Defaults to None (every point may be pooled).
            Shape (P,).

    Returns:
        BEVPoolIndices: Indices of the kept points, sorted by cell (the
        CPU's path), or of every point with the dropped ones in the drop
        cell (the GPUs', no host sync): pooled alike by :func:`bev_pool`.
    """
    if coords.dim() != 2 or coords.shape[1] != 3:
        raise ValueError('coords must have shape (P, 3), got '
                         f'{tuple(coords.shape)}')
    num_points = coords.shape[0]
    if batch_index.shape != (num_points, ) or feat_index.shape != (
            num_points, ):
        raise ValueError(f'batch_index and feat_index must have shape '
                         f'({num_points},), got {tuple(batch_index.shape)} '
                         f'and {tuple(feat_index.shape)}')
    if weight_index is None:
        weight_index = torch.arange(num_points, device=coords.device)
    size_x, size_y = bev_cell_size(point_cloud_range, bev_shape)
    xmin, ymin, zmin, _, _, zmax = (float(v) for v in point_cloud_range)
    num_y, num_x = int(bev_shape[0]), int(bev_shape[1])
    # Cells (x, y) of both axes at once: a GPU launches per operation.
    cell = torch.floor((coords[:, :2] - coords.new_tensor([xmin, ymin])) /
                       coords.new_tensor([size_x, size_y])).long()
    keep = ((cell >= 0) & (cell < cell.new_tensor([num_x, num_y]))).all(1)
    ix, iy = cell.unbind(1)
    # Not in place: an exported graph has no in-place bitwise and.
    keep = keep & ((coords[:, 2] >= zmin) & (coords[:, 2] < zmax)
                   & (batch_index >= 0) & (batch_index < batch_size))
    if valid is not None:
        keep = keep & valid
    rank = (batch_index.long() * num_y + iy) * num_x + ix
    if accelerator_path(coords):
        # No compaction, no sort: index_add needs neither.
        rank = torch.where(keep, rank,
                           torch.full_like(rank, batch_size * num_y * num_x))
        return BEVPoolIndices(weight_index.long(), feat_index.long(), rank,
                              int(batch_size), (num_y, num_x))
    rank = rank[keep]
    rank, order = torch.sort(rank, stable=True)
    kept = torch.nonzero(keep, as_tuple=False).squeeze(1)[order]
    return BEVPoolIndices(weight_index[kept].long(), feat_index[kept].long(),
                          rank, int(batch_size), (num_y, num_x))


def bev_pool(feats: Tensor, weights: Tensor,
             indices: BEVPoolIndices) -> Tensor:
    """Sum ``weight * feature`` of every kept point into its BEV cell.

    Args:
        feats (Tensor): Feature rows. Shape (Q, C).
        weights (Tensor): Flat point weights. Shape (P_all,).
        indices (BEVPoolIndices): From :func:`bev_pool_indices`.

    Returns:
        Tensor: Camera BEV features, differentiable w.r.t. ``feats`` and
        ``weights``. Shape (B, C, Y, X).
    """
    if feats.dim() != 2 or weights.dim() != 1:
        raise ValueError('bev_pool expects feats (Q, C) and weights (P,), '
                         f'got {tuple(feats.shape)} and '
                         f'{tuple(weights.shape)}')
    contrib = feats[indices.feat_index] * weights[indices.weight_index,
                                                  None].to(feats.dtype)
    # One row more: the drop cell's, cut off below.
    out = feats.new_zeros(indices.drop_cell + 1, feats.shape[1])
    if torch.onnx.is_in_onnx_export():
        # The exporter writes index_add as a ScatterElements without
        # reduction, where repeated cells overwrite each other; a
        # scatter_add over the feature rows is ScatterElements(add).
        return _to_bev(
            out.scatter_add(0, indices.bev_index[:, None].expand_as(contrib),
                            contrib), indices)
    return _to_bev(out.index_add(0, indices.bev_index, contrib), indices)


def _to_bev(out: Tensor, indices: BEVPoolIndices) -> Tensor:
    """Cell rows (B * Y * X + 1, C), the drop cell last, as (B, C, Y, X).
    """
    num_y, num_x = indices.bev_shape
    num_cells = indices.drop_cell
    return out[:num_cells].view(indices.batch_size, num_y, num_x,
                                -1).permute(0, 3, 1, 2).contiguous()


def bev_pool_mask(indices: BEVPoolIndices) -> Tensor:
    """Which BEV cells received at least one point.

    Args:
        indices (BEVPoolIndices): From :func:`bev_pool_indices`.

    Returns:
        Tensor: Bool mask. Shape (B, 1, Y, X).
    """
    num_y, num_x = indices.bev_shape
    mask = torch.zeros(
        indices.drop_cell + 1,
        dtype=torch.bool,
        device=indices.bev_index.device)
    mask[indices.bev_index] = True
    return mask[:-1].view(indices.batch_size, 1, num_y, num_x)


class BEVPoolIndexCache:
    """Reuses the pooling indices while the geometry does not change.

    BEVPoolv2 precomputes its indices once for a fixed camera set-up; this
    cache keeps the indices of the last geometry key (e.g. the camera
    matrices and the feature shape) and recomputes only when the key
    changes, so repeated inference on one rig pays the index cost once.

    Attributes:
        hits (int): Number of lookups served from the cache.
        misses (int): Number of lookups that recomputed the indices.
    """

    def __init__(self):
        self._key = None
        self._value = None
        self.hits = 0
        self.misses = 0

    @staticmethod
    def _same(key, cached) -> bool:
        if cached is None or len(key) != len(cached):
            return False
        for new, old in zip(key, cached):
            if isinstance(new, Tensor):
                if (not isinstance(old, Tensor) or new.shape != old.shape
                        or new.device != old.device
                        or not torch.equal(new, old)):
                    return False
            elif new != old:
                return False
        return True

    def get(self, key: Sequence,
            compute: Callable[[], BEVPoolIndices]) -> BEVPoolIndices:
        """Cached indices for ``key``, computed by ``compute()`` on a miss.

        Args:
            key (Sequence): Tensors and hashable values that fix the
                geometry.
            compute (Callable[[], BEVPoolIndices]): Builds the indices.

        Returns:
            BEVPoolIndices: The indices of this geometry.
        """
        key = tuple(key)
        if self._same(key, self._key):
            self.hits += 1
            return self._value
        self.misses += 1
        self._value = compute()
        self._key = tuple(
            k.detach().clone() if isinstance(k, Tensor) else k for k in key)
        return self._value

    def clear(self) -> None:
        """Forget the cached geometry."""
        self._key = None
        self._value = None
