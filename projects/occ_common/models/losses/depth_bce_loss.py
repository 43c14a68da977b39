"""BEVDepth's LiDAR-supervised depth loss (binary cross-entropy on bins)."""
from typing import Sequence

import torch
import torch.nn as nn
import torch.nn.functional as F
from mmdet3d.registry import MODELS
from torch import Tensor

from ...geometry.depth import (depth_to_bins, normalize_depth_bound,
                               num_depth_bins)
from ...utils.device_path import accelerator_path


@MODELS.register_module()
class DepthBCELoss(nn.Module):
    """Binary cross-entropy between predicted depth bins and LiDAR depth.

    The depth loss of Li et al., "BEVDepth: Acquisition of Reliable Depth
    for Multi-view 3D Object Detection" (AAAI 2023), its explicit depth
    supervision: targets come
    from :func:`depth_to_bins`, the BCE is summed over the D bins and
    averaged over the feature pixels that have a target (pixels without
    one contribute nothing).

    Args:
        depth_bound (Sequence[float]): ``(dmin, dmax, step)`` in metres.
            Defaults to (1.0, 50.0, 1.0).
        downsample (int): Stride of the depth features w.r.t. the image.
            Defaults to 16.
        loss_weight (float): Factor applied to the loss. Defaults to 3.0,
            BEVDepth's weight.
        nearest_bin (bool): Train each depth onto the bin whose lifted
            point is nearest to it, not BEVDepth's ``floor`` (half a bin
            closer on average; :func:`depth_to_bins`). Defaults to False.
    """

    def __init__(self,
                 depth_bound: Sequence[float] = (1.0, 50.0, 1.0),
                 downsample: int = 16,
                 loss_weight: float = 3.0,
                 nearest_bin: bool = False) -> None:
        super().__init__()
        self.num_bins = num_depth_bins(depth_bound)
        if int(downsample) != downsample or downsample < 1:
            raise ValueError('DepthBCELoss: expected a positive integer '
                             f'downsample, got {downsample!r}.')
        self.depth_bound = normalize_depth_bound(depth_bound)
        self.downsample = int(downsample)
        self.loss_weight = loss_weight
        self.nearest_bin = bool(nearest_bin)

    @property
    def loss_name(self) -> str:
        """Name of the term in a loss dict."""
        return 'loss_depth'

    def forward(self, depth_pred: Tensor, gt_depth: Tensor) -> Tensor:
        """Compute the loss.

        Args:
            depth_pred (Tensor): Depth-bin probabilities (after softmax).
                Shape (B*N, D, H / downsample, W / downsample).
            gt_depth (Tensor): Sparse LiDAR depth, 0 where there is no
                return. Shape (B*N, H, W).

        Returns:
            Tensor: Scalar loss; zero (with zero gradients) when no pixel
            has a target, NaN when a prediction with a target is NaN or
            infinite (for the non-finite loss guard to name).
        """
        if depth_pred.dim() != 4 or depth_pred.shape[1] != self.num_bins:
            raise ValueError(
                f'DepthBCELoss: expected depth_pred of shape (B*N, '
                f'{self.num_bins}, h, w) for depth_bound '
                f'{self.depth_bound}, got {tuple(depth_pred.shape)}.')
        expected = (gt_depth.shape[0], self.num_bins,
                    gt_depth.shape[-2] // self.downsample,
                    gt_depth.shape[-1] // self.downsample)
        if gt_depth.dim() != 3 or tuple(depth_pred.shape) != expected:
            raise ValueError(
                f'DepthBCELoss: depth_pred {tuple(depth_pred.shape)} does '
                f'not match gt_depth {tuple(gt_depth.shape)} at downsample='
                f'{self.downsample}; expected {expected}.')
        target, valid = depth_to_bins(gt_depth.float(), self.downsample,
                                      self.depth_bound, self.nearest_bin)
        pred = depth_pred.float().permute(0, 2, 3, 1).reshape(
            -1, self.num_bins)
        # The GPU path (and compiled code) keeps every cell, those without
        # a target masked out of the sum: selecting them would read their
        # number on the host (a sync, a graph break).
        masked = accelerator_path(pred)
        picked = pred if masked else pred[valid]
        # Non-finite probabilities (a diverging step, or NaN inputs) would
        # make BCE raise ("all elements of input should be between 0 and
        # 1"; a device assert on CUDA). BCE gets a stand-in of 0.5 there
        # and the loss becomes NaN, which NonFiniteLossHook reports with
        # the iteration and this term's name. No host sync is needed.
        finite = torch.isfinite(picked)
        safe = torch.where(finite, picked, torch.full_like(picked, 0.5))
        if masked:
            finite = finite | ~valid[:, None]
        # Over an empty selection the sum is a connected zero, so the
        # no-LiDAR batch needs no special case. CUDA autocast refuses
        # binary_cross_entropy outright (``--amp``), so it runs outside it,
        # in float32, as BEVDepth does.
        with torch.autocast(device_type=pred.device.type, enabled=False):
            bce = F.binary_cross_entropy(
                safe.clamp(0.0, 1.0), target if masked else target[valid],
                reduction='none')
        if masked:
            bce = torch.where(valid[:, None], bce, torch.zeros_like(bce))
        loss = bce.sum() / valid.sum().clamp(min=1)
        loss = torch.where(finite.all(), loss,
                           torch.full_like(loss, float('nan')))
        return self.loss_weight * loss
