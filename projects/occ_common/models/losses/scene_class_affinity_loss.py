"""Scene-class affinity loss (MonoScene) with a configurable empty class."""
from typing import Optional, Tuple, Union

import torch
from mmdet3d.registry import MODELS
from torch import Tensor

from ...utils.device_path import accelerator_path
from .occupancy_loss import OccupancyLossTerm
from .utils import SupervisedVoxels


def _neg_log_ratio(numerator: Tensor, denominator: Tensor,
                   eps: float) -> Tensor:
    """``-log((num + eps) / (den + eps))``, MonoScene's BCE against 1.

    MonoScene writes each term as ``BCE(ratio, 1) = -log(ratio)``, which is
    NaN when the denominator is zero (no positives in the batch) and inf
    when the numerator is (nothing correct). Adding eps to both sides makes
    an undefined ratio (0 / 0) count as perfect, gives every term a finite
    value and a finite gradient, and changes a well-defined ratio by
    O(eps). Since num <= den, the term is >= 0.
    """
    return -torch.log((numerator + eps) / (denominator + eps))


@MODELS.register_module()
class SceneClassAffinityLoss(OccupancyLossTerm):
    """Scene-class affinity loss of MonoScene, geometric or semantic.

    Implements Sec. 3.3.1 (the :math:`P_c, R_c, S_c` definitions and
    :math:`\\mathcal{L}_{scal}`) of Cao & de Charette, "MonoScene: Monocular
    3D Semantic Scene Completion" (CVPR 2022). For a class c with predicted
    probability :math:`p_i` and binary target :math:`t_i` over the
    supervised voxels of the whole batch,

    .. math::
        P_c = \\frac{\\sum p_i t_i}{\\sum p_i},\\quad
        R_c = \\frac{\\sum p_i t_i}{\\sum t_i},\\quad
        S_c = \\frac{\\sum (1 - p_i)(1 - t_i)}{\\sum (1 - t_i)},

    and the loss is :math:`-\\log P_c - \\log R_c - \\log S_c`.

    - ``mode='geo'``: one binary class "occupied", with
      :math:`p_i = 1 - \\mathrm{softmax}_{\\text{empty}}` and
      :math:`t_i = [y_i \\ne \\text{empty}]`.
    - ``mode='sem'``: the mean over the classes that occur in the target
      (MonoScene skips absent classes), with :math:`p_i` the softmax of
      class c. The empty class is one of them, as in MonoScene.

    Every ratio carries ``eps`` in numerator and denominator (see
    :func:`_neg_log_ratio`), so an all-empty batch gives a finite geometric
    loss (recall counts as perfect) and an all-ignored batch gives zero.

    Args:
        mode (str): ``'geo'`` or ``'sem'``. Defaults to 'geo'.
        empty_index (int): Label of empty space: 0 for SurroundOcc, 17
            (``free``) for Occ3D. Defaults to 0.
        ignore_index (int): Label of voxels without supervision.
            Defaults to 255.
        loss_weight (float): Factor applied to the loss. Defaults to 1.0.
        eps (float): Stabiliser of the ratios. Defaults to 1e-5.
    """

    def __init__(self,
                 mode: str = 'geo',
                 empty_index: int = 0,
                 ignore_index: int = 255,
                 loss_weight: float = 1.0,
                 eps: float = 1e-5) -> None:
        super().__init__(ignore_index, loss_weight)
        if mode not in ('geo', 'sem'):
            raise ValueError("SceneClassAffinityLoss: expected mode 'geo' "
                             f"or 'sem', got {mode!r}.")
        if eps <= 0:
            raise ValueError('SceneClassAffinityLoss: expected eps > 0, got '
                             f'{eps}.')
        self.mode = mode
        self.empty_index = empty_index
        self.eps = eps

    @property
    def loss_name(self) -> str:
        """Name of the term in a loss dict."""
        return f'loss_{self.mode}_scal'

    @property
    def error_name(self) -> str:
        """The term's name in error messages."""
        return f'SceneClassAffinityLoss({self.mode})'

    def check_classes(self, num_classes: int) -> None:
        """Also refuse an ``empty_index`` outside ``[0, C)``."""
        super().check_classes(num_classes)
        if not 0 <= self.empty_index < num_classes:
            raise ValueError(f'{self.error_name}: empty_index '
                             f'{self.empty_index} out of range for '
                             f'{num_classes} classes.')

    def loss_voxels(self, voxels: SupervisedVoxels) -> Tensor:
        """Scene-class affinity of the supervised voxels (unweighted)."""
        if self.mode == 'geo':
            return self._geo(voxels.probs, voxels.labels, voxels.mask)
        return self._sem(voxels.probs, voxels.labels, voxels.mask)

    def _terms(self, true_pos: Tensor, false_pos: Tensor, positives: Tensor,
               num_voxels: Union[int, Tensor]) -> Tensor:
        """Precision, recall and specificity terms, summed, per column.

        From the sums over the voxels, for positive-class probabilities
        :math:`p_i` and binary targets :math:`t_i`: precision
        :math:`TP / (TP + FP)`, recall :math:`TP / \\sum t_i` and
        specificity :math:`(\\sum (1 - t_i) - FP) / \\sum (1 - t_i)`, since
        :math:`\\sum (1 - p_i)(1 - t_i) = \\sum (1 - t_i) - FP`.

        Args:
            true_pos (Tensor): :math:`TP = \\sum p_i t_i`. Shape (K,).
            false_pos (Tensor): :math:`FP = \\sum p_i (1 - t_i)`. Shape (K,).
            positives (Tensor): :math:`\\sum t_i`. Shape (K,).
            num_voxels (int | Tensor): The number of voxels N.

        Returns:
            Tensor: One value per column. Shape (K,).
        """
        negatives = num_voxels - positives
        precision = _neg_log_ratio(true_pos, true_pos + false_pos, self.eps)
        recall = _neg_log_ratio(true_pos, positives, self.eps)
        specificity = _neg_log_ratio(negatives - false_pos, negatives,
                                     self.eps)
        return precision + recall + specificity

    @staticmethod
    def _mass(probs: Tensor, labels: Tensor,
              mask: Optional[Tensor] = None) -> Tuple[Tensor, Tensor]:
        """Each class's probability on its own voxels and on the others.

        One pass over the voxels: ``mass[y, c]`` sums :math:`p_{i,c}` over
        the voxels of label y. The off-diagonal sum is taken entry by entry
        (not as a column total minus the diagonal), so a small FP keeps its
        precision beside a large TP.

        Args:
            probs (Tensor): Softmax probabilities. Shape (N, C).
            labels (Tensor): Labels in ``[0, C)``. Shape (N,).
            mask (Tensor, optional): bool, the voxels that count (all by
                default). Shape (N,).

        Returns:
            tuple[Tensor, Tensor]: ``own[c]`` (the sum over voxels of
            class c) and ``other[c]`` (over the other voxels). Shape (C,).
        """
        num_classes = probs.shape[1]
        probs = probs.double()
        if mask is not None:
            probs = torch.where(mask[:, None], probs, 0.0)
        # float64: index_add sums one voxel at a time, and in float32 the
        # probabilities near 1 of ~3.6e5 empty voxels came out 1.3e-3 too
        # large (test_many_confident_voxels_keep_float32_precision).
        mass = probs.new_zeros(num_classes, num_classes).index_add(
            0, labels, probs)
        off_diagonal = 1.0 - torch.eye(
            num_classes, dtype=mass.dtype, device=probs.device)
        return mass.diagonal(), (mass * off_diagonal).sum(0)

    def _geo(self, probs: Tensor, labels: Tensor,
             mask: Optional[Tensor] = None) -> Tensor:
        """Geometric term: occupied (:math:`1 - p_{empty}`) vs empty, over
        the voxels of ``mask`` (all by default)."""
        occupied_prob = 1.0 - probs[:, self.empty_index]
        occupied = labels != self.empty_index
        empty = ~occupied
        num_voxels = labels.numel()
        if mask is not None:
            occupied, empty = occupied & mask, empty & mask
            num_voxels = mask.sum()
        zero = occupied_prob.new_zeros(())
        true_pos = torch.where(occupied, occupied_prob, zero).sum()
        false_pos = torch.where(empty, occupied_prob, zero).sum()
        positives = occupied.sum().to(probs.dtype)
        return self._terms(true_pos, false_pos, positives, num_voxels)

    def _sem(self, probs: Tensor, labels: Tensor,
             mask: Optional[Tensor] = None) -> Tensor:
        """Semantic term: mean over the classes present in the target, over
        the voxels of ``mask`` (all by default; the GPU path's)."""
        own, other = self._mass(probs, labels, mask)
        if accelerator_path(labels):
            # No host reads (bincount's maximum, three boolean indexes):
            # every class's terms, absent ones masked out of the mean.
            counts = torch.zeros(
                probs.shape[1], dtype=torch.long,
                device=labels.device).index_add_(
                    0, labels, torch.ones_like(labels)
                    if mask is None else mask.long())
            present = counts > 0
            terms = self._terms(
                own, other, counts.clamp(min=1).to(own.dtype),
                labels.numel() if mask is None else mask.sum())
            kept = torch.where(present, terms, torch.zeros_like(terms))
            num_present = present.sum().clamp(min=1).to(terms.dtype)
            return (kept.sum() / num_present).to(probs.dtype)
        counts = torch.bincount(labels, minlength=probs.shape[1])
        present = counts > 0
        return self._terms(own[present], other[present],
                           counts[present].to(own.dtype),
                           labels.numel()).mean().to(probs.dtype)
