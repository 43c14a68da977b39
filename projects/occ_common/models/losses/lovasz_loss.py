"""Lovasz-softmax loss over occupancy voxels.

mmdet3d 1.4's registered ``LovaszLoss`` is not reused: its flattening
unpacks exactly four axes, so logits of shape (B, C, X, Y, Z) raise a
ValueError; a batch with a single supervised voxel loses its class axis
(``squeeze`` of the index) and raises an IndexError; and an all-ignored
batch returns an empty (0, C) tensor instead of a scalar. This module
handles any number of spatial axes and returns a connected zero scalar for
an all-ignored batch.
"""
from typing import List, Optional, Sequence, Union

import torch
import torch.nn.functional as F
from mmdet3d.registry import MODELS
from torch import Tensor

from .occupancy_loss import OccupancyLossTerm
from .utils import supervised_voxels, zero_with_grad


def lovasz_softmax_flat(
        probs: Tensor,
        labels: Tensor,
        classes: Union[str, Sequence[int]] = 'present',
        class_weight: Optional[Sequence[float]] = None) -> Optional[Tensor]:
    """Lovasz-softmax loss of supervised voxels, all classes at once.

    Implements eq. 12 and Algorithm 1 of Berman et al., "The Lovasz-Softmax
    loss" (CVPR 2018): for each class c the errors
    :math:`m_i = |[y_i = c] - p_{i,c}|` are sorted in decreasing order and
    dotted with the gradient of the Lovasz extension of the Jaccard loss,
    :math:`g_k = J_k - J_{k-1}` with
    :math:`J_k = 1 - |F_c \\setminus \\pi_{1..k}| / |F_c \\cup \\pi_{1..k}|`
    (F_c the voxels of class c, :math:`\\pi_{1..k}` the k largest errors).

    Args:
        probs (Tensor): Softmax probabilities. Shape (N, C).
        labels (Tensor): Labels in ``[0, C)``. Shape (N,).
        classes (str | Sequence[int]): ``'present'`` averages over the
            classes that occur in ``labels``, ``'all'`` over every class, or
            an explicit list of class indices. Defaults to 'present'.
        class_weight (Sequence[float], optional): Per-class factor applied
            before averaging. Defaults to None.

    Returns:
        Tensor | None: Scalar loss, or None when no class is selected (no
        supervised voxel with ``'present'``).
    """
    num_classes = probs.shape[1]
    total = torch.bincount(labels, minlength=num_classes)
    if classes == 'present':
        selected = total > 0
    elif classes == 'all':
        selected = torch.ones_like(total, dtype=torch.bool)
    else:
        selected = torch.zeros_like(total, dtype=torch.bool)
        selected[list(classes)] = True
    if not bool(selected.any()):
        return None
    # Only the selected classes are sorted: each class's term depends on
    # its own column alone, and the sort is most of this loss's time.
    columns = selected.nonzero()[:, 0]
    fg = F.one_hot(labels, num_classes)[:, columns].to(probs.dtype)
    errors = (fg - probs[:, columns]).abs()
    total = total[columns].to(probs.dtype)
    with torch.no_grad():
        # Past the last member of F_c in the sorted order the intersection
        # is 0, so J_k = 1 from there on and g_k = 0: those voxels add
        # nothing to the loss or its gradient. They are exactly the
        # non-members whose error is below every member's, so only errors
        # >= the smallest member error are sorted (for a class without
        # members, only the largest error, whose g is 1). Early in training
        # and for the small classes this drops most voxels.
        member_min = torch.where(fg > 0, errors,
                                 errors.new_tensor(float('inf'))).amin(0)
        cut = torch.where(total > 0, member_min, errors.amax(0))
        kept = errors >= cut
    per_class = []
    for j in range(len(columns)):
        rows = kept[:, j].nonzero()[:, 0]
        errors_sorted, order = torch.sort(
            errors[rows, j], descending=True)
        with torch.no_grad():
            fg_sorted = fg[rows, j][order]
            intersection = total[j] - fg_sorted.cumsum(0)
            # The union is >= 1 from the first voxel on: either the class
            # has voxels (total >= 1) or the first sorted voxel is a
            # non-member.
            union = total[j] + (1.0 - fg_sorted).cumsum(0)
            jaccard = 1.0 - intersection / union
            grad = torch.cat([jaccard[:1], jaccard[1:] - jaccard[:-1]])
        per_class.append((errors_sorted * grad).sum())
    per_class = torch.stack(per_class)
    if class_weight is not None:
        per_class = per_class * per_class.new_tensor(
            list(class_weight))[columns]
    return per_class.mean()


@MODELS.register_module()
class OccLovaszLoss(OccupancyLossTerm):
    """Lovasz-softmax loss for logits with any number of spatial axes.

    A surrogate of the per-class Jaccard index (Berman et al., CVPR 2018,
    eq. 12), averaged over classes; all supervised voxels of the batch are
    pooled (no per-sample averaging), as in the reference implementation.

    Args:
        classes (str | Sequence[int]): ``'present'``, ``'all'`` or a list
            of class indices to average over. Defaults to 'present'.
        class_weight (Sequence[float], optional): Per-class factor.
            Defaults to None.
        ignore_index (int): Label of voxels without supervision.
            Defaults to 255.
        loss_weight (float): Factor applied to the loss. Defaults to 1.0.
    """

    loss_name = 'loss_lovasz'

    def __init__(self,
                 classes: Union[str, Sequence[int]] = 'present',
                 class_weight: Optional[Sequence[float]] = None,
                 ignore_index: int = 255,
                 loss_weight: float = 1.0) -> None:
        super().__init__(ignore_index, loss_weight, class_weight)
        if isinstance(classes, str):
            if classes not in ('present', 'all'):
                raise ValueError("OccLovaszLoss: expected classes 'present',"
                                 f" 'all' or a list of ints, got {classes!r}")
        elif not all(isinstance(c, int) for c in classes):
            raise ValueError('OccLovaszLoss: expected a list of int class '
                             f'indices, got {classes!r}.')
        self.classes: Union[str, List[int]] = (
            classes if isinstance(classes, str) else list(classes))

    def forward(self, logits: Tensor, target: Tensor) -> Tensor:
        """Lovasz-softmax of the supervised voxels (see
        :class:`~.occupancy_loss.OccupancyLossTerm` for the shapes)."""
        # Shapes are checked by supervised_voxels; this needs only C.
        num_classes = logits.shape[1] if logits.dim() >= 2 else None
        if num_classes is not None and not isinstance(
                self.classes, str) and any(c < 0 or c >= num_classes
                                           for c in self.classes):
            raise ValueError(f'OccLovaszLoss: classes {self.classes} out of '
                             f'range for {num_classes} classes.')
        picked = supervised_voxels(logits, target, self.ignore_index,
                                   'OccLovaszLoss', self.class_weight)
        if picked is None:
            return zero_with_grad(logits)
        scores, labels = picked
        probs = F.softmax(scores, dim=1)
        loss = lovasz_softmax_flat(probs, labels, self.classes,
                                   self.class_weight)
        if loss is None:
            return zero_with_grad(logits)
        return self.loss_weight * loss
