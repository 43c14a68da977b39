"""Input checks and flattening shared by the occupancy losses."""
import os
from typing import Optional, Tuple

import torch
import torch.nn.functional as F
from torch import Tensor

from ...utils.device_path import HOST_CHECKS_ENV, accelerator_path


def flatten_logits(logits: Tensor, target: Tensor,
                   loss_name: str) -> Tuple[Tensor, Tensor]:
    """Move the class axis last and flatten logits and labels.

    Args:
        logits (Tensor): Class scores. Shape (B, C, X, Y, Z), any number of
            spatial axes, or (N, C).
        target (Tensor): Integer labels. Shape (B, X, Y, Z) matching the
            logits without the class axis, or (N,).
        loss_name (str): Name of the calling loss, used in error messages.

    Returns:
        tuple[Tensor, Tensor]: Logits of shape (M, C) and labels of shape
        (M,), where M is the number of voxels. Neither input is modified.

    Raises:
        ValueError: If the shapes do not match or the labels are not
            integers.
    """
    if logits.dim() < 2:
        raise ValueError(f'{loss_name}: expected logits of shape (N, C) or '
                         f'(B, C, X, Y, Z), got {tuple(logits.shape)}.')
    expected = (logits.shape[0], ) + tuple(logits.shape[2:])
    if tuple(target.shape) != expected:
        raise ValueError(f'{loss_name}: expected target of shape {expected} '
                         f'for logits of shape {tuple(logits.shape)}, got '
                         f'{tuple(target.shape)}.')
    if target.dtype.is_floating_point or target.dtype == torch.bool:
        raise ValueError(f'{loss_name}: expected an integer target, got '
                         f'{target.dtype}.')
    num_classes = logits.shape[1]
    flat_logits = logits.movedim(1, -1).reshape(-1, num_classes)
    return flat_logits, target.reshape(-1).long()


def check_labels(target: Tensor, num_classes: int, ignore_index: int,
                 loss_name: str) -> Tensor:
    """Check that every label is a class index or ``ignore_index``.

    Args:
        target (Tensor): Integer labels, any shape.
        num_classes (int): Number of classes C.
        ignore_index (int): Label of voxels without supervision.
        loss_name (str): Name of the calling loss, used in error messages.

    Returns:
        Tensor: Bool mask of the supervised voxels, same shape as target.

    Raises:
        ValueError: If a label is outside ``[0, C)`` and not the ignore
            index.
    """
    valid = target != ignore_index
    bad = valid & ((target < 0) | (target >= num_classes))
    if accelerator_path(target) and \
            os.environ.get(HOST_CHECKS_ENV) != '1':
        # A host read per loss and scale would make the host wait for the
        # device; the labels were checked when loaded, so this is queued
        # on the device (check_index_range says more).
        torch._assert_async(~bad.any())
        return valid
    if bool(bad.any()):
        found = torch.unique(target[bad]).tolist()
        raise ValueError(f'{loss_name}: expected labels in [0, {num_classes})'
                         f' or the ignore index {ignore_index}, found '
                         f'{found[:10]}.')
    return valid


def zero_with_grad(tensor: Tensor) -> Tensor:
    """A zero scalar that is still connected to ``tensor``'s graph.

    Returning it for a batch without supervised voxels keeps ``backward``
    valid (all gradients zero) under DDP, which expects every parameter
    that produced the logits to receive a gradient.
    """
    return tensor.sum() * 0.0


class SupervisedVoxels:
    """The supervised voxels of one prediction, as the loss terms read them.

    A composed loss flattens and selects the voxels once and hands this to
    each of its terms; the (log-)softmax is computed on first use and then
    shared, so four terms on a 200 x 200 x 16 grid cost one selection and
    one softmax (and their backward passes), not four.

    The CPU's code path selects the M supervised voxels. On GPUs (and in
    compiled code, :mod:`projects.occ_common.utils.device_path`) selecting
    them would read M on the host (a sync, and a graph break under
    ``torch.compile``), so every voxel is kept and ``mask`` says which are
    supervised; the terms leave the others out of every sum (their labels
    read 0, a valid class index).

    Args:
        scores (Tensor): float32 logits of the supervised voxels (of every
            voxel, with ``mask``). Shape (M, C).
        labels (Tensor): Their labels in ``[0, C)``. Shape (M,).
        mask (Tensor, optional): bool, which voxels are supervised.
            Defaults to None (all). Shape (M,).
    """

    def __init__(self, scores: Tensor, labels: Tensor,
                 mask: Optional[Tensor] = None) -> None:
        self.scores = scores
        self.labels = labels
        self.mask = mask
        self._log_probs: Optional[Tensor] = None
        self._probs: Optional[Tensor] = None

    def only(self, values: Tensor) -> Tensor:
        """``values`` (M, ...) with 0 at the voxels that are not supervised
        (no gradient reaches them)."""
        if self.mask is None:
            return values
        mask = self.mask.view(-1, *([1] * (values.dim() - 1)))
        return torch.where(mask, values, torch.zeros_like(values))

    def mean(self, values: Tensor) -> Tensor:
        """Mean of per-voxel ``values`` (M,) over the supervised voxels (0
        when there are none)."""
        if self.mask is None:
            return values.mean()
        return self.only(values).sum() / self.mask.sum().clamp(min=1)

    @property
    def log_probs(self) -> Tensor:
        """Log-softmax over the classes. Shape (M, C)."""
        if self._log_probs is None:
            self._log_probs = F.log_softmax(self.scores, dim=1)
        return self._log_probs

    @property
    def probs(self) -> Tensor:
        """Softmax over the classes (the exp of :attr:`log_probs`). Shape
        (M, C)."""
        if self._probs is None:
            self._probs = self.log_probs.exp()
        return self._probs


def supervised_voxels(logits: Tensor, target: Tensor, ignore_index: int,
                      loss_name: str) -> Optional[SupervisedVoxels]:
    """The float32 logits and labels of the supervised voxels.

    The common prologue of the occupancy losses: shape and dtype checks
    (:func:`flatten_logits`) and label range (:func:`check_labels`), then
    selection of the voxels whose label is not ``ignore_index``. Selecting
    rather than masking keeps ignored voxels out of the softmax gradient
    entirely.

    Args:
        logits (Tensor): Class scores. Shape (B, C, X, Y, Z) or (N, C).
        target (Tensor): Integer labels. Shape (B, X, Y, Z) or (N,).
        ignore_index (int): Label of voxels without supervision.
        loss_name (str): Name of the calling loss, used in error messages.

    Returns:
        SupervisedVoxels | None: The M supervised voxels, or None when
        M = 0; on the GPU path every voxel and the mask of the supervised
        ones (see :class:`SupervisedVoxels`), whatever M.
    """
    flat_logits, flat_target = flatten_logits(logits, target, loss_name)
    valid = check_labels(flat_target, flat_logits.shape[1], ignore_index,
                         loss_name)
    if accelerator_path(flat_target):
        return SupervisedVoxels(
            flat_logits.float(),
            torch.where(valid, flat_target, torch.zeros_like(flat_target)),
            valid)
    # One host read (the count, from nonzero), not three (any() and two
    # boolean indexes).
    rows = valid.nonzero().squeeze(1)
    if rows.numel() == 0:
        return None
    return SupervisedVoxels(
        flat_logits.index_select(0, rows).float(),
        flat_target.index_select(0, rows))
