"""Majority-vote down-sampling of occupancy labels."""
from typing import Optional

import torch
from torch import Tensor

from ...utils.device_path import accelerator_path


def downsample_occupancy_gt(gt: Tensor,
                            factor: int,
                            empty_index: int = 0,
                            ignore_index: int = 255,
                            num_classes: Optional[int] = None) -> Tensor:
    """Down-sample a label grid by a majority vote over occupied labels.

    Each ``factor``^3 block becomes

    1. the most frequent *occupied* label among its voxels, if it has any
       (neither empty nor ignored voxels vote, so a thin object is kept even
       when most of its block is empty);
    2. otherwise ``empty_index``, if it has an empty voxel (the block is
       empty apart from ignored voxels);
    3. otherwise ``ignore_index`` (every voxel of the block is ignored).

    Ties between occupied labels go to the smallest class index
    (``torch.argmax`` returns the first maximum), so the result is
    deterministic. Comparable projects instead index the full-resolution
    grid with strided or scattered writes, where whichever voxel is written
    last wins; that drops small objects and depends on the write order.

    The vote is vectorised: the blocks are gathered into rows and counted
    with one ``scatter_add``, with no Python loop over voxels.

    Args:
        gt (Tensor): Integer labels in ``[0, C)`` or ``ignore_index``.
            Shape (B, X, Y, Z) or (X, Y, Z).
        factor (int): Down-sampling factor; X, Y and Z must be multiples.
        empty_index (int): Label of empty space. Defaults to 0.
        ignore_index (int): Label of unsupervised voxels. Defaults to 255.
        num_classes (int, optional): C, when the caller knows it: on the
            GPU path the vote then needs no host read of the largest label
            (nor of the negative-label and all-ignored checks, queued on
            the device instead). Defaults to None (read from ``gt``).

    Returns:
        Tensor: Labels of the same dtype and leading shape,
        Shape (B, X / factor, Y / factor, Z / factor) (or without B).

    Raises:
        ValueError: If the shape, dtype or factor is invalid, or a label is
            negative and not the ignore index.
    """
    if int(factor) != factor or factor < 1:
        raise ValueError('downsample_occupancy_gt: expected a positive '
                         f'integer factor, got {factor!r}.')
    factor = int(factor)
    if gt.dtype.is_floating_point or gt.dtype == torch.bool:
        raise ValueError('downsample_occupancy_gt: expected integer labels,'
                         f' got {gt.dtype}.')
    unbatched = gt.dim() == 3
    grid = gt.unsqueeze(0) if unbatched else gt
    if grid.dim() != 4:
        raise ValueError('downsample_occupancy_gt: expected gt of shape '
                         f'(B, X, Y, Z) or (X, Y, Z), got {tuple(gt.shape)}.')
    batch, size_x, size_y, size_z = grid.shape
    if size_x % factor or size_y % factor or size_z % factor:
        raise ValueError(
            f'downsample_occupancy_gt: grid {(size_x, size_y, size_z)} is '
            f'not a multiple of factor={factor}.')
    if factor == 1:
        return gt.clone()
    out_shape = (batch, size_x // factor, size_y // factor,
                 size_z // factor)
    blocks = grid.reshape(batch, out_shape[1], factor, out_shape[2], factor,
                          out_shape[3], factor)
    blocks = blocks.permute(0, 1, 3, 5, 2, 4, 6).reshape(-1, factor**3)
    blocks = blocks.long()

    ignored = blocks == ignore_index
    if num_classes is not None and accelerator_path(blocks):
        # Without host reads: the vote below gives an all-ignored block
        # ignore_index by itself.
        torch._assert_async((ignored | ((blocks >= 0) &
                                        (blocks < num_classes))).all())
        num_slots = max(int(num_classes), empty_index + 1)
    else:
        if bool((~ignored & (blocks < 0)).any()):
            raise ValueError('downsample_occupancy_gt: found negative labels'
                             f' other than ignore_index={ignore_index}.')
        if bool(ignored.all()):
            result = torch.full(out_shape, ignore_index, dtype=gt.dtype,
                                device=gt.device)
            return result[0] if unbatched else result
        num_slots = max(int(blocks[~ignored].max()), empty_index) + 1
    # Ignored voxels are counted in an extra last slot so that one
    # scatter_add counts everything; that slot is then left out of the vote.
    slots = torch.where(ignored, torch.full_like(blocks, num_slots), blocks)
    counts = torch.zeros(
        blocks.shape[0], num_slots + 1, dtype=torch.long,
        device=blocks.device)
    counts.scatter_add_(1, slots, torch.ones_like(slots))
    occupied = counts[:, :num_slots].clone()
    occupied[:, empty_index] = 0
    winner = occupied.argmax(dim=1)
    has_occupied = occupied.amax(dim=1) > 0
    has_empty = counts[:, empty_index] > 0
    fallback = torch.where(has_empty, torch.full_like(winner, empty_index),
                           torch.full_like(winner, ignore_index))
    result = torch.where(has_occupied, winner, fallback)
    result = result.reshape(out_shape).to(gt.dtype)
    return result[0] if unbatched else result
