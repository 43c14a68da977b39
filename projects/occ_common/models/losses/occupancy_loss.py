"""The composed occupancy loss of both models, single- or multi-scale.

A head holds one :class:`OccupancyLoss` (SDG-OCC's channel-to-height head)
or :class:`MultiScaleOccupancyLoss` (OccCylindrical's eq. 18). It builds its
terms (focal, Lovasz, scene-class affinity, ...) and gives each the
``empty_index`` / ``ignore_index`` it is configured with, so a config
states those labels once; a term that was given other labels is refused.
Every model names its loss-dict keys the same way: ``{term}{_s<l>}{suffix}``
(``loss_focal``, ``loss_focal_s0``, ``loss_focal_teacher``).
"""
import inspect
import re
from typing import Dict, List, Optional, Sequence, Union

import torch
import torch.nn as nn
from mmdet3d.registry import MODELS
from torch import Tensor

from ...utils.precision import float32_math
from .occupancy_gt_downsample import downsample_occupancy_gt
from .utils import SupervisedVoxels, supervised_voxels, zero_with_grad

#: Label arguments a composed loss hands to the terms that take them.
SHARED_LABELS = ('empty_index', 'ignore_index')


class OccupancyLossTerm(nn.Module):
    """Base of the per-voxel occupancy losses (focal, Lovasz, SCAL).

    Called as ``term(logits, target) -> scalar`` with logits Shape
    (B, C, X, Y, Z) or (N, C) and integer targets Shape (B, X, Y, Z) or
    (N,), labels in ``[0, C)`` or ``ignore_index``; an all-ignored input
    gives a zero still connected to the logits. Subclasses implement
    :meth:`loss_voxels` on the :class:`~.utils.SupervisedVoxels`, which
    :class:`OccupancyLoss` selects once for all its terms, and extend
    :meth:`check_classes` with their own checks of C.

    Args:
        ignore_index (int): Label of voxels without supervision.
            Defaults to 255.
        loss_weight (float): Factor applied to the loss. Defaults to 1.0.
        class_weight (Sequence[float], optional): One weight per class.
            Defaults to None (all ones).
    """

    #: Key of the term in a loss dict.
    loss_name = 'loss_occ'

    def __init__(self,
                 ignore_index: int = 255,
                 loss_weight: float = 1.0,
                 class_weight: Optional[Sequence[float]] = None) -> None:
        super().__init__()
        self.ignore_index = ignore_index
        self.loss_weight = loss_weight
        self.class_weight = (None if class_weight is None else
                             [float(w) for w in class_weight])

    @property
    def error_name(self) -> str:
        """The term's name in error messages."""
        return type(self).__name__

    def check_classes(self, num_classes: int) -> None:
        """Refuse settings that do not fit C classes.

        Raises:
            ValueError: If ``class_weight`` does not hold C weights.
        """
        if (self.class_weight is not None
                and len(self.class_weight) != num_classes):
            raise ValueError(
                f'{self.error_name}: expected {num_classes} class weights '
                f'for logits with {num_classes} classes, got '
                f'{len(self.class_weight)}.')

    def loss_voxels(self, voxels: SupervisedVoxels) -> Optional[Tensor]:
        """The unweighted loss of the supervised voxels.

        Args:
            voxels (SupervisedVoxels): At least one voxel.

        Returns:
            Tensor | None: Scalar, or None when the term has nothing to
            measure (e.g. no selected class present).
        """
        raise NotImplementedError(
            f'{type(self).__name__} does not implement loss_voxels.')

    def weighted(self, voxels: Optional[SupervisedVoxels],
                 logits: Tensor) -> Tensor:
        """``loss_weight`` times :meth:`loss_voxels`, or a connected zero.

        Args:
            voxels (SupervisedVoxels | None): The supervised voxels of
                ``logits``; None when there are none.
            logits (Tensor): The prediction they come from.

        Returns:
            Tensor: Scalar.
        """
        loss = None if voxels is None else self.loss_voxels(voxels)
        if loss is None:
            return zero_with_grad(logits)
        if voxels.mask is not None:
            # The GPU path cannot return early without supervised voxels
            # (SupervisedVoxels): it gives the same connected zero.
            loss = torch.where(voxels.mask.any(), loss,
                               zero_with_grad(logits))
        return self.loss_weight * loss

    @float32_math
    def forward(self, logits: Tensor, target: Tensor) -> Tensor:
        """The term on one prediction (shapes in the class docstring)."""
        if logits.dim() >= 2:
            self.check_classes(logits.shape[1])
        voxels = supervised_voxels(logits, target, self.ignore_index,
                                   self.error_name)
        return self.weighted(voxels, logits)


def term_name(loss: nn.Module) -> str:
    """Key prefix of a loss: its ``loss_name`` or its snake-cased class.

    Args:
        loss (nn.Module): A loss term.

    Returns:
        str: E.g. ``'loss_focal'``; ``MyThingLoss`` without a ``loss_name``
        gives ``'loss_my_thing'``.
    """
    name = getattr(loss, 'loss_name', None)
    if name:
        return name
    snake = re.sub(r'(?<!^)(?=[A-Z])', '_', type(loss).__name__).lower()
    snake = snake[:-len('_loss')] if snake.endswith('_loss') else snake
    return f'loss_{snake}'


def _accepted(cfg: dict, names: Sequence[str]) -> List[str]:
    """Which of ``names`` the registered class of ``cfg`` takes."""
    cls = MODELS.get(cfg['type']) if isinstance(cfg['type'],
                                                str) else cfg['type']
    if cls is None:
        return []
    params = inspect.signature(cls).parameters
    return [n for n in names if n in params]


@MODELS.register_module()
class OccupancyLoss(nn.Module):
    """Sum of occupancy loss terms on one prediction, one key per term.

    Args:
        losses (Sequence[dict | nn.Module]): Configs (built from
            ``MODELS``) or modules of the terms, each called as
            ``loss(logits, target) -> scalar``. A config without
            ``empty_index`` / ``ignore_index`` gets this loss's, where its
            class takes them.
        empty_index (int): Label of empty space. Defaults to 0.
        ignore_index (int): Label of unsupervised voxels. Defaults to 255.
    """

    def __init__(self,
                 losses: Sequence[Union[dict, nn.Module]],
                 empty_index: int = 0,
                 ignore_index: int = 255) -> None:
        super().__init__()
        if not losses:
            raise ValueError(f'{type(self).__name__}: expected at least one '
                             'loss config.')
        self.empty_index = empty_index
        self.ignore_index = ignore_index
        labels = dict(empty_index=empty_index, ignore_index=ignore_index)
        terms = []
        for loss in losses:
            if not isinstance(loss, nn.Module):
                loss = MODELS.build(
                    loss,
                    default_args={
                        n: labels[n]
                        for n in _accepted(loss, SHARED_LABELS)
                    })
            terms.append(loss)
        self.losses = nn.ModuleList(terms)
        self.term_names: List[str] = [term_name(m) for m in self.losses]
        if len(set(self.term_names)) != len(self.term_names):
            raise ValueError(f'{type(self).__name__}: two losses share a '
                             f'name in {self.term_names}; give them '
                             'distinct loss_name properties.')
        # A term that disagrees with the GT's empty / ignore labels would be
        # silently wrong (e.g. Occ3D GT with a SurroundOcc SCAL), so refuse.
        for loss in self.losses:
            for attr in SHARED_LABELS:
                value = getattr(loss, attr, None)
                if value is not None and value != labels[attr]:
                    raise ValueError(
                        f'{type(self).__name__}: {type(loss).__name__} '
                        f'has {attr}={value} but the composed loss has '
                        f'{attr}={labels[attr]}.')

    def terms(self, logits: Tensor, target: Tensor, key_suffix: str,
              factor: float = 1.0) -> Dict[str, Tensor]:
        """Every term on one prediction, divided by ``factor``.

        Args:
            logits (Tensor): Shape (B, C, X, Y, Z).
            target (Tensor): Labels. Shape (B, X, Y, Z).
            key_suffix (str): Appended to every term's name.
            factor (float): Divisor of every term. Defaults to 1.

        Returns:
            dict[str, Tensor]: ``{term_name + key_suffix: scalar}``.
        """
        voxels = None
        shared = [t for t in self.losses if isinstance(t, OccupancyLossTerm)]
        if shared:
            # Flatten, select and softmax once for every term.
            for term in shared:
                if logits.dim() >= 2:
                    term.check_classes(logits.shape[1])
            voxels = supervised_voxels(logits, target, self.ignore_index,
                                       type(self).__name__)
        return {
            name + key_suffix:
            (loss.weighted(voxels, logits) if isinstance(
                loss, OccupancyLossTerm) else loss(logits, target)) / factor
            for name, loss in zip(self.term_names, self.losses)
        }

    @float32_math
    def forward(self,
                logits: Tensor,
                target: Tensor,
                suffix: str = '') -> Dict[str, Tensor]:
        """Compute every term.

        Args:
            logits (Tensor): Class scores. Shape (B, C, X, Y, Z).
            target (Tensor): Labels, ``ignore_index`` where unsupervised.
                Shape (B, X, Y, Z).
            suffix (str): Appended to every key (e.g. ``'_teacher'``).
                Defaults to ''.

        Returns:
            dict[str, Tensor]: ``'{loss_name}{suffix}'`` -> scalar, e.g.
            ``'loss_focal'``.
        """
        return self.terms(logits, target, suffix)


@MODELS.register_module()
class MultiScaleOccupancyLoss(OccupancyLoss):
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
        losses (Sequence[dict | nn.Module]): See :class:`OccupancyLoss`.
        num_scales (int): Number of scales. Defaults to 4.
        empty_index (int): Label of empty space, also for the
            down-sampling. Defaults to 0.
        ignore_index (int): Label of unsupervised voxels. Defaults to 255.
    """

    def __init__(self,
                 losses: Sequence[Union[dict, nn.Module]],
                 num_scales: int = 4,
                 empty_index: int = 0,
                 ignore_index: int = 255) -> None:
        if num_scales < 1:
            raise ValueError('MultiScaleOccupancyLoss: expected num_scales '
                             f'>= 1, got {num_scales}.')
        super().__init__(losses, empty_index, ignore_index)
        self.num_scales = num_scales

    @float32_math
    def forward(self,
                logits: Sequence[Tensor],
                target: Tensor,
                suffix: str = '') -> Dict[str, Tensor]:
        """Compute every loss at every scale.

        Args:
            logits (Sequence[Tensor]): One prediction per scale, finest
                first; scale l has Shape (B, C, X / 2^l, Y / 2^l, Z / 2^l).
            target (Tensor): Full-resolution labels. Shape (B, X, Y, Z).
            suffix (str): Appended to every key. Defaults to ''.

        Returns:
            dict[str, Tensor]: ``'{loss_name}_s{l}{suffix}'`` -> the
            weighted scalar loss of scale l, e.g. ``'loss_focal_s0'``.
        """
        if len(logits) != self.num_scales:
            raise ValueError(
                f'MultiScaleOccupancyLoss: expected {self.num_scales} '
                f'predictions (finest first), got {len(logits)}.')
        terms: Dict[str, Tensor] = {}
        for level, scale_logits in enumerate(logits):
            factor = 2**level
            scale_target = downsample_occupancy_gt(
                target, factor, self.empty_index, self.ignore_index,
                num_classes=scale_logits.shape[1])
            if tuple(scale_logits.shape[2:]) != tuple(scale_target.shape[1:]):
                raise ValueError(
                    f'MultiScaleOccupancyLoss: scale {level} predicts a '
                    f'grid {tuple(scale_logits.shape[2:])} but the GT '
                    f'{tuple(target.shape[1:])} down-sampled by {factor} is '
                    f'{tuple(scale_target.shape[1:])}.')
            terms.update(
                self.terms(scale_logits, scale_target, f'_s{level}{suffix}',
                           factor))
        return terms
