"""Multi-scale occupancy supervision (OccCylindrical eq. 18)."""
import re
from typing import Dict, List, Sequence, Union

import torch.nn as nn
from mmdet3d.registry import MODELS
from torch import Tensor

from .occupancy_gt_downsample import downsample_occupancy_gt


def _term_name(loss: nn.Module) -> str:
    """Key prefix of a loss: its ``loss_name`` or its snake-cased class."""
    name = getattr(loss, 'loss_name', None)
    if name:
        return name
    snake = re.sub(r'(?<!^)(?=[A-Z])', '_', type(loss).__name__).lower()
    snake = snake[:-len('_loss')] if snake.endswith('_loss') else snake
    return f'loss_{snake}'


@MODELS.register_module()
class MultiScaleOccupancyLoss(nn.Module):
    """Apply occupancy losses at every decoder scale, weighted 1 / 2^l.

    Implements eq. 18 of OccCylindrical,
    :math:`\\mathcal{L} = \\sum_l \\frac{1}{2^l} \\mathcal{L}_l`, where
    scale l (0 = finest) predicts a grid 2^l times coarser than the GT and
    :math:`\\mathcal{L}_l` is the sum of the configured losses at that
    scale. The GT of scale l is obtained from the full-resolution GT by
    :func:`downsample_occupancy_gt` with factor 2^l: a majority vote over
    the occupied labels of each block (empty only when the whole block is
    empty, ignored voxels do not vote), not the last-write-wins indexing
    comparable projects use.

    Args:
        losses (Sequence[dict | nn.Module]): Configs (built from
            ``MODELS``) or modules of the losses applied at every scale,
            each called as ``loss(logits, target) -> scalar``.
        num_scales (int): Number of scales. Defaults to 4.
        empty_index (int): Label of empty space for the down-sampling.
            Defaults to 0.
        ignore_index (int): Label of unsupervised voxels. Defaults to 255.
    """

    def __init__(self,
                 losses: Sequence[Union[dict, nn.Module]],
                 num_scales: int = 4,
                 empty_index: int = 0,
                 ignore_index: int = 255) -> None:
        super().__init__()
        if not losses:
            raise ValueError('MultiScaleOccupancyLoss: expected at least '
                             'one loss config.')
        if num_scales < 1:
            raise ValueError('MultiScaleOccupancyLoss: expected num_scales '
                             f'>= 1, got {num_scales}.')
        self.losses = nn.ModuleList([
            loss if isinstance(loss, nn.Module) else MODELS.build(loss)
            for loss in losses
        ])
        self.num_scales = num_scales
        self.empty_index = empty_index
        self.ignore_index = ignore_index
        self.term_names: List[str] = [_term_name(m) for m in self.losses]
        if len(set(self.term_names)) != len(self.term_names):
            raise ValueError('MultiScaleOccupancyLoss: two losses share a '
                             f'name in {self.term_names}; give them '
                             'distinct loss_name properties.')
        # A loss that disagrees with the GT's empty / ignore labels would be
        # silently wrong (e.g. Occ3D GT with a SurroundOcc SCAL), so refuse.
        for loss in self.losses:
            for attr in ('empty_index', 'ignore_index'):
                value = getattr(loss, attr, None)
                if value is not None and value != getattr(self, attr):
                    raise ValueError(
                        f'MultiScaleOccupancyLoss: {type(loss).__name__} '
                        f'has {attr}={value} but the wrapper has '
                        f'{attr}={getattr(self, attr)}.')

    def forward(self, logits: Sequence[Tensor],
                gt: Tensor) -> Dict[str, Tensor]:
        """Compute every loss at every scale.

        Args:
            logits (Sequence[Tensor]): One prediction per scale, finest
                first; scale l has Shape (B, C, X / 2^l, Y / 2^l, Z / 2^l).
            gt (Tensor): Full-resolution labels. Shape (B, X, Y, Z).

        Returns:
            dict[str, Tensor]: ``'{loss_name}_s{l}'`` -> the weighted
            scalar loss of scale l, e.g. ``'loss_focal_s0'``.
        """
        if len(logits) != self.num_scales:
            raise ValueError(
                f'MultiScaleOccupancyLoss: expected {self.num_scales} '
                f'predictions (finest first), got {len(logits)}.')
        terms: Dict[str, Tensor] = {}
        for level, scale_logits in enumerate(logits):
            factor = 2**level
            target = downsample_occupancy_gt(gt, factor, self.empty_index,
                                             self.ignore_index)
            if tuple(scale_logits.shape[2:]) != tuple(target.shape[1:]):
                raise ValueError(
                    f'MultiScaleOccupancyLoss: scale {level} predicts a '
                    f'grid {tuple(scale_logits.shape[2:])} but the GT '
                    f'{tuple(gt.shape[1:])} down-sampled by {factor} is '
                    f'{tuple(target.shape[1:])}.')
            for name, loss in zip(self.term_names, self.losses):
                terms[f'{name}_s{level}'] = loss(scale_logits,
                                                 target) / factor
        return terms
