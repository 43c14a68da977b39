"""Fused depth lift + per-voxel max pooling (OccCylindrical steps 3 and 5).

The pseudo-3D point cloud of OccCylindrical is the outer product of the
depth distribution ``V_depth`` and the context ``V_context``: point
``(m, d, y, x)`` (camera image ``m``, depth bin ``d``, feature pixel
``(y, x)``) carries the feature ``depth[m, d, y, x] * context[m, :, y, x]``.
Eqs. 6-7 then max-pool the points of every cylindrical voxel. At the paper's
size that is 6 x 50 x 58 x 100 = 1.74 M points, so materialising the
``(points, C)`` feature tensor dominates memory.

:class:`LiftMaxPoolFunction` never builds it: its forward walks over chunks
of points, keeps the running per-voxel, per-channel maximum and then the
index of the winning point, and its backward routes the gradient to
``depth`` and ``context`` through those indices; when no gradient is
needed, :func:`lift_max` keeps the maxima only (one pass, no winners).
:func:`naive_lift_max_pool`
is the reference: outer product, then max pooling.

Tie-break rule (identical in both paths): when several points of a voxel
reach the same maximum in a channel, the point with the smallest flat index
``((m * D + d) * h + y) * w + x`` wins and alone receives the gradient.
(``torch.scatter_reduce``'s own ``amax`` backward would instead split the
gradient evenly between tied points.) Empty voxels are 0 and receive no
gradient. Forward values of the two paths are bitwise equal; gradients are
equal up to the order of floating-point summation (bitwise when the
arithmetic is exact).
"""
from typing import Iterator, Tuple

import torch
from torch import Tensor
from torch.autograd import Function
from torch.autograd.function import once_differentiable

from projects.occ_common.models.layers import cell_max
from projects.occ_common.models.layers.cell_max import quiet_index_reduce
from projects.occ_common.utils.device_path import (accelerator_path,
                                                   check_index_range)


def _check_voxel_index(voxel_idx: Tensor, num_voxels: int) -> None:
    if voxel_idx.dtype != torch.long:
        raise ValueError('voxel indices must be int64 (-1 = outside), got '
                         f'{voxel_idx.dtype}')
    check_index_range(voxel_idx, -1, num_voxels,
                      'voxel indices (-1 = outside)')


def voxel_max_pool(feats: Tensor, voxel_idx: Tensor,
                   num_voxels: int) -> Tensor:
    """Max-pool point features per voxel and channel (eqs. 6-7).

    Uses the module's tie-break rule: the lowest point index wins.

    Args:
        feats (Tensor): Point features. Shape (P, C).
        voxel_idx (Tensor): Voxel of each point, -1 for points outside the
            volume. Shape (P,).
        num_voxels (int): Number of voxels ``V``.

    Returns:
        Tensor: Pooled features, 0 for empty voxels. Shape (V, C).
    """
    if feats.dim() != 2 or voxel_idx.shape != feats.shape[:1]:
        raise ValueError('voxel_max_pool expects feats (P, C) and voxel_idx '
                         f'(P,), got {tuple(feats.shape)} and '
                         f'{tuple(voxel_idx.shape)}')
    _check_voxel_index(voxel_idx, num_voxels)
    if not (torch.is_grad_enabled() and feats.requires_grad):
        # Inference: the maxima alone; the int64 (V, C) winners and
        # (P, C) candidates exist only to route a gradient.
        return _voxel_max(feats, voxel_idx, num_voxels)
    num_points, channels = feats.shape
    winner = _winners(feats.detach(), voxel_idx,
                      torch.arange(num_points, device=feats.device),
                      num_voxels, num_points)
    # Row P of the padded features is the zero of empty voxels; gather
    # sends each output's gradient to its winning point only.
    padded = torch.cat([feats, feats.new_zeros(1, channels)], dim=0)
    return padded.gather(0, winner)


def _voxel_max(feats: Tensor, voxel_idx: Tensor, num_voxels: int) -> Tensor:
    """Per-voxel, per-channel maximum, 0 for empty voxels (no winners)."""
    # Points outside go to a spare row V, dropped at the end: no copy of
    # the features for a mask.
    rows = torch.where(voxel_idx >= 0, voxel_idx, num_voxels)
    out = cell_max(feats, rows, num_voxels + 1)
    return out[:num_voxels]


def _winners(feats: Tensor, voxel_idx: Tensor, point_ids: Tensor,
             num_voxels: int, sentinel: int) -> Tensor:
    """Lowest-index argmax per voxel and channel, ``sentinel`` if empty."""
    channels = feats.shape[1]
    if accelerator_path(feats):
        # Points outside go to a spare row V instead of being selected:
        # no size that the host must read.
        idx = torch.where(voxel_idx >= 0, voxel_idx,
                          num_voxels)[:, None].expand(-1, channels)
        vmax = feats.new_full((num_voxels + 1, channels), float('-inf'))
        vmax.scatter_reduce_(0, idx, feats, 'amax')
        cand = torch.where(feats == vmax.gather(0, idx), point_ids[:, None],
                           sentinel)
        winner = torch.full((num_voxels + 1, channels), sentinel,
                            dtype=torch.long, device=feats.device)
        return winner.scatter_reduce_(0, idx, cand, 'amin')[:num_voxels]
    inside = voxel_idx >= 0
    idx = voxel_idx[inside][:, None].expand(-1, channels)
    vals = feats[inside]
    vmax = feats.new_full((num_voxels, channels), float('-inf'))
    vmax.scatter_reduce_(0, idx, vals, 'amax')
    cand = torch.where(vals == vmax.gather(0, idx), point_ids[inside][:,
                                                                      None],
                       sentinel)
    winner = torch.full((num_voxels, channels),
                        sentinel,
                        dtype=torch.long,
                        device=feats.device)
    return winner.scatter_reduce_(0, idx, cand, 'amin')


def naive_lift_max_pool(depth: Tensor, context: Tensor, voxel_idx: Tensor,
                        num_voxels: int) -> Tensor:
    """Reference path: materialise every pseudo point, then max-pool.

    Args:
        depth (Tensor): Depth distribution. Shape (M, D, h, w).
        context (Tensor): Context features. Shape (M, C, h, w).
        voxel_idx (Tensor): Voxel of every point, -1 outside.
            Shape (M, D, h, w).
        num_voxels (int): Number of voxels ``V``.

    Returns:
        Tensor: Pooled features. Shape (V, C).
    """
    _check_lift_inputs(depth, context, voxel_idx)
    channels = context.shape[1]
    # (M, D, 1, h, w) * (M, 1, C, h, w): the outer product of eq. 5's
    # outputs, laid out point-major in the flat index order (m, d, y, x).
    feats = depth.unsqueeze(2) * context.unsqueeze(1)
    feats = feats.permute(0, 1, 3, 4, 2).reshape(-1, channels)
    return voxel_max_pool(feats, voxel_idx.reshape(-1), num_voxels)


def _check_lift_inputs(depth: Tensor, context: Tensor,
                       voxel_idx: Tensor) -> None:
    if depth.dim() != 4 or context.dim() != 4:
        raise ValueError('lift-pool expects depth (M, D, h, w) and context '
                         f'(M, C, h, w), got {tuple(depth.shape)} and '
                         f'{tuple(context.shape)}')
    if depth.shape[0] != context.shape[0] or \
            depth.shape[2:] != context.shape[2:]:
        raise ValueError('depth and context must share (M, h, w), got '
                         f'{tuple(depth.shape)} and {tuple(context.shape)}')
    if voxel_idx.shape != depth.shape:
        raise ValueError(f'voxel_idx must have the depth shape '
                         f'{tuple(depth.shape)}, got {tuple(voxel_idx.shape)}')


def _chunks(num_images: int, num_bins: int, num_pixels: int,
            chunk_size: int) -> Iterator[Tuple[int, int, int]]:
    """Yield ``(image, start, end)`` ranges of whole depth bins."""
    bins_per_chunk = max(1, chunk_size // max(num_pixels, 1))
    for m in range(num_images):
        for d0 in range(0, num_bins, bins_per_chunk):
            d1 = min(num_bins, d0 + bins_per_chunk)
            yield m, d0 * num_pixels, d1 * num_pixels


class _LiftPoints:
    """The pseudo points of a lift, chunk by chunk (never all at once).

    Args:
        depth (Tensor): Shape (M, D, h, w).
        context (Tensor): Shape (M, C, h, w).
        voxel_idx (Tensor): Shape (M, D, h, w), -1 outside.
        num_voxels (int): ``V``; points outside go to the spare row ``V``
            so that chunks stay dense (no masking or gathers per point).
        chunk_size (int): Points per chunk, rounded to whole depth bins.
    """

    def __init__(self, depth: Tensor, context: Tensor, voxel_idx: Tensor,
                 num_voxels: int, chunk_size: int) -> None:
        self.num_images, self.num_bins, height, width = depth.shape
        self.channels = context.shape[1]
        self.num_pixels = height * width
        self.total = self.num_images * self.num_bins * self.num_pixels
        self.chunk_size = chunk_size
        # Pixel-major context rows (a copy the size of the context) keep
        # every chunk's product contiguous.
        self.rows = context.permute(0, 2, 3, 1).reshape(
            self.num_images, self.num_pixels, self.channels).contiguous()
        points = self.num_bins * self.num_pixels
        self.depth = depth.reshape(self.num_images, points)
        idx = voxel_idx.reshape(self.num_images, points)
        self.idx = torch.where(idx >= 0, idx, num_voxels)

    def __iter__(self) -> Iterator[Tuple[Tensor, Tensor, int]]:
        """Yield ``(features (n, C), voxel rows (n,), first point id)``."""
        for m, start, end in _chunks(self.num_images, self.num_bins,
                                     self.num_pixels, self.chunk_size):
            bins = (end - start) // self.num_pixels
            # Same float product as the naive outer product, so the values
            # (and hence the winners) agree bitwise.
            feats = self.depth[m, start:end].view(
                bins, self.num_pixels, 1) * self.rows[m].unsqueeze(0)
            yield (feats.view(-1, self.channels), self.idx[m, start:end],
                   m * self.num_bins * self.num_pixels + start)

    def max(self, num_voxels: int) -> Tensor:
        """Running per-voxel maximum, -inf where empty. Shape (V + 1, C)."""
        # index_reduce_ takes one index per row: on CPU it is ~2x faster
        # than scatter_reduce_ and needs no (points, C) index tensor.
        vmax = self.depth.new_full((num_voxels + 1, self.channels),
                                   float('-inf'))
        with quiet_index_reduce():
            for feats, vox, _ in self:
                vmax.index_reduce_(0, vox, feats, 'amax')
        return vmax

    def winners(self, vmax: Tensor, id_dtype: torch.dtype) -> Tensor:
        """Lowest point id reaching ``vmax``, ``total`` where none does.

        The second pass over the points; only a backward needs it.
        Shape (V + 1, C).
        """
        winner = torch.full(
            vmax.shape, self.total, dtype=id_dtype, device=vmax.device)
        with quiet_index_reduce():
            for feats, vox, first in self:
                ids = torch.arange(
                    first,
                    first + feats.shape[0],
                    dtype=id_dtype,
                    device=vmax.device)
                cand = torch.where(feats == vmax.index_select(0, vox),
                                   ids.unsqueeze(1), self.total)
                winner.index_reduce_(0, vox, cand, 'amin')
        return winner

    def occupied(self, num_voxels: int) -> Tensor:
        """Voxels at least one point reaches. Shape (V + 1,) bool."""
        hit = torch.zeros(
            num_voxels + 1, dtype=torch.bool, device=self.idx.device)
        return hit.index_fill_(0, self.idx.reshape(-1), True)


def lift_max(depth: Tensor, context: Tensor, voxel_idx: Tensor,
             num_voxels: int, chunk_size: int) -> Tensor:
    """Forward-only fused lift-pool: the maxima without the winners.

    The values of :class:`LiftMaxPoolFunction` (bitwise: the same maxima,
    0 in empty voxels) from one pass over the points instead of two and
    without the ``(V, C)`` winner buffer; :func:`lift_max_pool` takes it
    when no gradient is needed. A non-empty voxel whose maximum is NaN
    keeps the NaN here (the Function gives it 0: no point equals NaN).

    Args:
        depth (Tensor): Shape (M, D, h, w).
        context (Tensor): Shape (M, C, h, w).
        voxel_idx (Tensor): Shape (M, D, h, w), -1 outside.
        num_voxels (int): ``V``.
        chunk_size (int): Points per chunk.

    Returns:
        Tensor: Pooled features, 0 in empty voxels. Shape (V, C).
    """
    points = _LiftPoints(depth, context, voxel_idx, num_voxels, chunk_size)
    vmax = points.max(num_voxels)
    empty = ~points.occupied(num_voxels)
    return vmax.masked_fill_(empty.unsqueeze(1), 0.0)[:num_voxels]


class LiftMaxPoolFunction(Function):
    """Autograd Function of the fused lift + voxel max pool.

    Forward memory is ``O(V * C)`` for the output and the winner indices
    plus ``O(chunk_size * C)`` of temporaries, instead of
    ``O(M * D * h * w * C)``.
    """

    @staticmethod
    def forward(ctx, depth: Tensor, context: Tensor, voxel_idx: Tensor,
                num_voxels: int, chunk_size: int) -> Tensor:
        """See :func:`lift_max_pool`."""
        points = _LiftPoints(depth, context, voxel_idx, num_voxels,
                             chunk_size)
        total = points.total
        # Point ids are stored in int32 when they fit: it halves the one
        # O(V * C) buffer the backward needs.
        id_dtype = torch.int32 if total < 2**31 - 1 else torch.long
        vmax = points.max(num_voxels)
        winner = points.winners(vmax, id_dtype)[:num_voxels]
        out = vmax[:num_voxels].masked_fill_(winner == total, 0.0)
        ctx.save_for_backward(depth, context, winner)
        ctx.chunk_size = chunk_size
        return out

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_out: Tensor):
        """Route ``grad_out`` (V, C) to the winning points' inputs."""
        depth, context, winner = ctx.saved_tensors
        num_images, num_bins, height, width = depth.shape
        channels = context.shape[1]
        num_pixels = height * width
        total = num_images * num_bins * num_pixels
        rows = context.permute(0, 2, 3, 1).reshape(-1, channels)
        depth_flat = depth.reshape(-1)
        # Fresh flat buffers: index_add_ must never write into a copy.
        grad_depth = depth.new_zeros(depth.numel())
        grad_rows = context.new_zeros(context.numel())
        # Blocks of whole voxels bound the temporaries (~60 bytes per
        # voxel-channel entry, far less than the forward's per point).
        block = max(1, 16 * ctx.chunk_size // max(channels, 1))
        # GPUs (and compiled code) take every entry, those without a
        # winner adding a 0 to point 0: no host read of how many have one.
        every = accelerator_path(grad_out)
        # No points (no images): no winners, nothing to route.
        for v0 in range(0, winner.shape[0] if total else 0, block):
            win = winner[v0:v0 + block].long()
            grad = grad_out[v0:v0 + block]
            hit = win != total
            if every:
                pid = torch.where(hit, win, 0).reshape(-1)
                chan = torch.arange(
                    channels, device=win.device).repeat(win.shape[0])
                g = torch.where(hit, grad, 0.0).reshape(-1)
            elif not bool(hit.any()):
                continue
            else:
                pid = win[hit]
                chan = torch.nonzero(hit)[:, 1]
                g = grad[hit]
            image = pid // (num_bins * num_pixels)
            pixel = image * num_pixels + pid % num_pixels
            if ctx.needs_input_grad[0]:
                grad_depth.index_add_(0, pid,
                                      g * rows[pixel, chan])
            if ctx.needs_input_grad[1]:
                grad_rows.index_add_(0, pixel * channels + chan,
                                     g * depth_flat[pid])
        grad_context = grad_rows.reshape(num_images, height, width,
                                         channels).permute(0, 3, 1, 2)
        return (grad_depth.reshape(depth.shape)
                if ctx.needs_input_grad[0] else None,
                grad_context.contiguous() if ctx.needs_input_grad[1] else
                None, None, None, None)


def lift_max_pool(depth: Tensor,
                  context: Tensor,
                  voxel_idx: Tensor,
                  num_voxels: int,
                  fused: bool = True,
                  chunk_size: int = 16384) -> Tensor:
    """Lift ``depth x context`` to pseudo points and max-pool per voxel.

    Implements steps 3 and 5 (eqs. 6-7) of OccCylindrical for the camera
    branch. Both paths follow the tie-break rule of this module.

    Args:
        depth (Tensor): Depth distribution ``V_depth``. Shape (M, D, h, w).
        context (Tensor): Context ``V_context``. Shape (M, C, h, w).
        voxel_idx (Tensor): Flat voxel index of each point (bins' 3D points
            in the cylinder grid), -1 outside. int64. Shape (M, D, h, w).
        num_voxels (int): Number of voxels ``V`` (all samples together).
        fused (bool): Use the memory-saving fused path: the autograd
            Function when a gradient is needed, else the single pass of
            :func:`lift_max`. False selects :func:`naive_lift_max_pool`.
            Defaults to True.
        chunk_size (int): Points per chunk of the fused path (rounded to
            whole depth bins, at least one bin of one image). Defaults to
            16384: at C = 64 its temporaries stay near 20 MiB.

    Returns:
        Tensor: Pooled features, 0 in empty voxels. Shape (V, C).
    """
    _check_lift_inputs(depth, context, voxel_idx)
    _check_voxel_index(voxel_idx, num_voxels)
    if chunk_size < 1:
        raise ValueError(f'chunk_size must be positive, got {chunk_size}')
    if not fused:
        return naive_lift_max_pool(depth, context, voxel_idx, num_voxels)
    context = context.to(depth.dtype)
    if not (torch.is_grad_enabled() and
            (depth.requires_grad or context.requires_grad)):
        return lift_max(depth, context, voxel_idx, num_voxels, chunk_size)
    return LiftMaxPoolFunction.apply(depth, context, voxel_idx, num_voxels,
                                     chunk_size)
