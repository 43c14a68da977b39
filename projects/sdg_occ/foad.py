"""Fusion-to-occupancy-driven active distillation (FOAD).

Implements eqs. 5-8 of SDG-OCC (Duan et al., CVPR 2025, Sec. 3.5). A
LiDAR-dominant fusion BEV is the teacher and the camera BEV the student.
Cells are split into the active region AR = fused & img (both the teacher
and the camera saw the cell) and the inactive region IR = fused & ~img
(only the teacher saw it); the per-cell weight is alpha on AR and
rho * beta on IR with rho = N_AR / N_IR, which balances the two regions
whatever their sizes, and 0 elsewhere. The distillation is one-way: the
teacher is detached, so only the student learns from it.

Eq. 8 compares the raw features. Ours differ in scale by construction: the
student is the camera BEV after ``camera_bev_conv`` (conv + BatchNorm over
the whole map, std 4.2 on the cells the camera covers at initialisation of
the tiny SDG-KL), the teacher the fused BEV (ReLU(BN(conv)) times a sigmoid
gate: non-negative, mean +0.5, std 1.2). Most of the initial loss (9.7 of
10.2) is that mismatch, and its gradient into the camera branch was 8-16x
the occupancy loss's (measured 2026-11-28, 4143e91).
``normalize='channel'`` compares the two after standardising each channel
of each sample over the teacher's cells (zero mean, unit variance; as PKD,
Cao et al., NeurIPS 2022, does for detector features): the loss then
measures the features' pattern, which is what the student's BEV encoder
and head (BatchNorm first) read, and is at most 4 per cell and channel
whatever the scales.
"""
from typing import Optional

import torch
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import Tensor

from projects.occ_common.utils.precision import float32_math


def _check_mask(mask: Tensor, name: str) -> None:
    if mask.dim() != 4 or mask.shape[1] != 1:
        raise ValueError(f'{name} must have shape (B, 1, H, W), got '
                         f'{tuple(mask.shape)}')


#: FOADDistillLoss's ``normalize`` modes.
NORMALIZE_MODES = ('none', 'channel')


def standardize_channels(feats: Tensor, cells: Tensor,
                         eps: float = 1e-5) -> Tensor:
    """Standardise every channel of every sample over its ``cells``.

    Args:
        feats (Tensor): Shape (B, C, H, W).
        cells (Tensor): Cells whose statistics are used, bool.
            Shape (B, 1, H, W).
        eps (float): Added to the variance. Defaults to 1e-5.

    Returns:
        Tensor: ``(feats - mean) / sqrt(var + eps)``, with the mean and the
        (biased) variance over ``cells`` of each (sample, channel); a
        sample without cells keeps mean 0 and variance 0. Shape (B, C, H,
        W).
    """
    weight = cells.to(feats.dtype)
    count = weight.sum(dim=(2, 3), keepdim=True).clamp(min=1)
    mean = (feats * weight).sum(dim=(2, 3), keepdim=True) / count
    var = ((feats - mean).pow(2) * weight).sum(
        dim=(2, 3), keepdim=True) / count
    return (feats - mean) * torch.rsqrt(var + eps)


def foad_weights(fused_mask: Tensor, img_mask: Tensor, alpha: float,
                 beta: float) -> Tensor:
    """Per-cell distillation weights W of eqs. 5-7.

    For each sample separately: AR = fused & img, IR = fused & ~img,
    rho = N_AR / N_IR (counts over that sample's cells), and
    ``W = alpha`` on AR, ``W = rho * beta`` on IR, 0 elsewhere. When IR is
    empty rho is never used, so it is set to 0 instead of dividing by 0.

    Args:
        fused_mask (Tensor): Cells the teacher (fused BEV) covers, bool.
            Shape (B, 1, H, W).
        img_mask (Tensor): Cells the camera BEV covers, bool.
            Shape (B, 1, H, W).
        alpha (float): Weight of the active region.
        beta (float): Weight of the inactive region before balancing.

    Returns:
        Tensor: Weights, float32. Shape (B, 1, H, W).
    """
    _check_mask(fused_mask, 'fused_mask')
    _check_mask(img_mask, 'img_mask')
    if fused_mask.shape != img_mask.shape:
        raise ValueError('fused_mask and img_mask must have the same shape, '
                         f'got {tuple(fused_mask.shape)} and '
                         f'{tuple(img_mask.shape)}')
    fused_mask = fused_mask.bool()
    img_mask = img_mask.bool()
    active = fused_mask & img_mask
    inactive = fused_mask & ~img_mask
    n_active = active.flatten(1).sum(1).float()
    n_inactive = inactive.flatten(1).sum(1).float()
    rho = torch.where(n_inactive > 0, n_active / n_inactive.clamp(min=1),
                      torch.zeros_like(n_active)).view(-1, 1, 1, 1)
    return active.float() * alpha + inactive.float() * rho * beta


@MODELS.register_module()
class FOADDistillLoss(BaseModule):
    """Weighted, one-way feature distillation of eq. 8.

    ``loss = loss_weight * sum_{b, c, y, x} W (T - S)^2 / (C * N_fused)``,
    where T is the teacher (detached), S the student, W from
    :func:`foad_weights`, and the denominator is the number of channels
    times the number N_fused of cells of the fused mask in the batch
    (clamped to >= 1): a mean squared error over the teacher-covered cells
    in which alpha and beta keep their absolute scale.

    Args:
        alpha (float): Weight of the active region. Defaults to 1.0.
        beta (float): Weight of the inactive region before the N_AR / N_IR
            balancing. Defaults to 1.0.
        loss_weight (float): Multiplier of the loss. Defaults to 1.0.
        normalize (str): ``'none'`` compares the features as they are (eq.
            8 as written); ``'channel'`` first standardises student and
            teacher per sample and channel over the teacher's cells
            (:func:`standardize_channels`; the module docstring says why).
            Defaults to 'none'.
        init_cfg (dict, optional): mmengine initialisation config.
    """

    def __init__(self,
                 alpha: float = 1.0,
                 beta: float = 1.0,
                 loss_weight: float = 1.0,
                 normalize: str = 'none',
                 init_cfg: Optional[dict] = None):
        super().__init__(init_cfg=init_cfg)
        if normalize not in NORMALIZE_MODES:
            raise ValueError(f'FOADDistillLoss: normalize must be one of '
                             f'{NORMALIZE_MODES}, got {normalize!r}')
        self.normalize = normalize
        self.alpha = alpha
        self.beta = beta
        self.loss_weight = loss_weight

    @float32_math
    def forward(self, student: Tensor, teacher: Tensor, fused_mask: Tensor,
                img_mask: Tensor) -> Tensor:
        """Distillation loss of the student BEV towards the teacher BEV.

        Args:
            student (Tensor): Camera BEV. Shape (B, C, H, W).
            teacher (Tensor): Fused BEV; gradients do not flow into it.
                Shape (B, C, H, W).
            fused_mask (Tensor): Teacher-covered cells, bool.
                Shape (B, 1, H, W).
            img_mask (Tensor): Camera-covered cells, bool.
                Shape (B, 1, H, W).

        Returns:
            Tensor: Scalar loss.
        """
        if student.shape != teacher.shape or student.dim() != 4:
            raise ValueError('FOADDistillLoss expects student and teacher of '
                             'the same shape (B, C, H, W), got '
                             f'{tuple(student.shape)} and '
                             f'{tuple(teacher.shape)}')
        weights = foad_weights(fused_mask, img_mask, self.alpha, self.beta)
        if weights.shape[0] != student.shape[0] \
                or weights.shape[2:] != student.shape[2:]:
            raise ValueError('FOADDistillLoss masks must be (B, 1, H, W) = '
                             f'({student.shape[0]}, 1, {student.shape[2]}, '
                             f'{student.shape[3]}), got '
                             f'{tuple(weights.shape)}')
        teacher = teacher.detach()
        if self.normalize == 'channel':
            cells = fused_mask.bool()
            teacher = standardize_channels(teacher, cells)
            student = standardize_channels(student, cells)
        sq_err = (teacher - student).pow(2)
        total = (weights.to(sq_err.dtype) * sq_err).sum()
        denom = float(student.shape[1]) * fused_mask.bool().sum().clamp(
            min=1).to(sq_err.dtype)
        return self.loss_weight * total / denom
