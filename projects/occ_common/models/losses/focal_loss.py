"""Softmax focal loss over occupancy voxels."""
from typing import Optional, Sequence

import torch
from mmdet3d.registry import MODELS
from torch import Tensor

from .occupancy_loss import OccupancyLossTerm
from .utils import SupervisedVoxels


@MODELS.register_module()
class OccFocalLoss(OccupancyLossTerm):
    """Multi-class (softmax) focal loss with an ignore label.

    Implements eq. 5 of Lin et al., "Focal Loss for Dense Object Detection"
    (ICCV 2017) over the softmax of C classes, with the class weight
    :math:`w_c` in place of the scalar :math:`\\alpha`:

    .. math::
        L = \\frac{1}{|V|} \\sum_{i \\in V} -w_{y_i} (1 - p_{i,y_i})^\\gamma
            \\log p_{i,y_i},

    where V is the set of voxels whose label is not ``ignore_index``. The
    sum is divided by the number of supervised voxels (not by the sum of
    their weights), so the class weights rescale classes against each other
    and the overall scale. With ``gamma=0`` and no weights this is the
    cross-entropy. The inputs are never modified: ignored voxels are
    excluded by a mask, not by overwriting their labels.

    Args:
        gamma (float): Focusing parameter. Defaults to 2.0.
        class_weight (Sequence[float], optional): One weight per class.
            Defaults to None (all ones).
        ignore_index (int): Label of voxels without supervision.
            Defaults to 255.
        loss_weight (float): Factor applied to the loss. Defaults to 1.0.
    """

    loss_name = 'loss_focal'

    def __init__(self,
                 gamma: float = 2.0,
                 class_weight: Optional[Sequence[float]] = None,
                 ignore_index: int = 255,
                 loss_weight: float = 1.0) -> None:
        super().__init__(ignore_index, loss_weight, class_weight)
        if gamma < 0:
            raise ValueError(f'OccFocalLoss: expected gamma >= 0, got '
                             f'{gamma}.')
        self.gamma = float(gamma)

    def loss_voxels(self, voxels: SupervisedVoxels) -> Tensor:
        """Focal loss of the supervised voxels (unweighted)."""
        labels = voxels.labels
        log_p = voxels.log_probs.gather(1, labels[:, None])[:, 0]
        p = log_p.exp()
        loss = -((1.0 - p)**self.gamma) * log_p
        if self.class_weight is not None:
            weight = torch.tensor(
                self.class_weight, dtype=loss.dtype, device=loss.device)
            loss = loss * weight[labels]
        return voxels.mean(loss)
