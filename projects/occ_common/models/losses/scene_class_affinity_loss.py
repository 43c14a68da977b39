"""Scene-class affinity loss (MonoScene) with a configurable empty class."""
import torch
import torch.nn.functional as F
from mmdet3d.registry import MODELS
from torch import Tensor

from .occupancy_loss import OccupancyLossTerm
from .utils import supervised_voxels, zero_with_grad


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

    def forward(self, logits: Tensor, target: Tensor) -> Tensor:
        """Scene-class affinity of the supervised voxels (see
        :class:`~.occupancy_loss.OccupancyLossTerm` for the shapes)."""
        name = f'SceneClassAffinityLoss({self.mode})'
        # Shapes are checked by supervised_voxels; this needs only C.
        num_classes = logits.shape[1] if logits.dim() >= 2 else None
        if num_classes is not None and not 0 <= self.empty_index < num_classes:
            raise ValueError(f'{name}: empty_index {self.empty_index} out of '
                             f'range for {num_classes} classes.')
        picked = supervised_voxels(logits, target, self.ignore_index, name)
        if picked is None:
            return zero_with_grad(logits)
        scores, labels = picked
        probs = F.softmax(scores, dim=1)
        if self.mode == 'geo':
            loss = self._geo(probs, labels)
        else:
            loss = self._sem(probs, labels)
        return self.loss_weight * loss

    def _terms(self, p: Tensor, t: Tensor) -> Tensor:
        """Precision, recall and specificity terms, summed, per column.

        Args:
            p (Tensor): Probability of the positive class. Shape (N, K).
            t (Tensor): Binary target as float. Shape (N, K).

        Returns:
            Tensor: One value per column. Shape (K,).
        """
        true_pos = (p * t).sum(0)
        precision = _neg_log_ratio(true_pos, p.sum(0), self.eps)
        recall = _neg_log_ratio(true_pos, t.sum(0), self.eps)
        true_neg = ((1.0 - p) * (1.0 - t)).sum(0)
        specificity = _neg_log_ratio(true_neg, (1.0 - t).sum(0), self.eps)
        return precision + recall + specificity

    def _geo(self, probs: Tensor, labels: Tensor) -> Tensor:
        """Geometric term: occupied vs empty."""
        occupied_prob = 1.0 - probs[:, self.empty_index]
        occupied = (labels != self.empty_index).to(probs.dtype)
        return self._terms(occupied_prob[:, None], occupied[:, None])[0]

    def _sem(self, probs: Tensor, labels: Tensor) -> Tensor:
        """Semantic term: mean over the classes present in the target.

        All present classes at once, as columns (one pass over the voxels
        instead of one per class).
        """
        present = torch.unique(labels)
        targets = (labels[:, None] == present[None]).to(probs.dtype)
        return self._terms(probs[:, present], targets).mean()
