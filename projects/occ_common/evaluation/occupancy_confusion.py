"""Confusion matrices and IoU scores of semantic occupancy grids.

Everything the occupancy metric reports is derived from a C x C confusion
matrix (rows: ground truth, columns: prediction) accumulated over the
dataset, so per-rank results reduce by summation.
"""
from typing import Sequence

import numpy as np
import torch
from torch import Tensor


def confusion_matrix(gt: Tensor, pred: Tensor, num_classes: int) -> Tensor:
    """Count (ground truth, prediction) pairs.

    Args:
        gt (Tensor): Labels in ``[0, C)``, already filtered to the counted
            voxels. Shape (N,).
        pred (Tensor): Predicted labels in ``[0, C)``. Shape (N,).
        num_classes (int): C.

    Returns:
        Tensor: int64 counts on the inputs' device, ``[g, p]`` = number of
        voxels with GT g predicted as p. Shape (C, C).
    """
    index = gt.long() * num_classes + pred.long()
    counts = torch.bincount(index, minlength=num_classes * num_classes)
    return counts.reshape(num_classes, num_classes)


def per_class_iou(confusion: np.ndarray) -> np.ndarray:
    """IoU of every class, NaN for a class absent from GT and prediction.

    :math:`IoU_c = TP_c / (TP_c + FP_c + FN_c)`, where every voxel counted
    in the matrix (including those of the empty / free class) is a false
    positive of its predicted class and a false negative of its GT class.

    Args:
        confusion (np.ndarray): Counts, rows GT. Shape (C, C).

    Returns:
        np.ndarray: float64 IoU in [0, 1] or NaN. Shape (C,).
    """
    confusion = np.asarray(confusion, dtype=np.float64)
    true_pos = np.diag(confusion)
    union = confusion.sum(0) + confusion.sum(1) - true_pos
    iou = np.full(true_pos.shape, np.nan)
    present = union > 0
    iou[present] = true_pos[present] / union[present]
    return iou


def mean_iou(confusion: np.ndarray, classes: Sequence[int]) -> float:
    """Mean IoU over ``classes``, skipping classes that never occur.

    A class with no voxel in either GT or prediction has an undefined IoU
    (0 / 0); it is left out of the mean, as Occ3D's ``nanmean`` does,
    rather than counted as 0 or 1.

    Args:
        confusion (np.ndarray): Counts, rows GT. Shape (C, C).
        classes (Sequence[int]): Class indices to average over.

    Returns:
        float: Mean IoU in [0, 1], or NaN when no listed class occurs.
    """
    iou = per_class_iou(confusion)[list(classes)]
    iou = iou[~np.isnan(iou)]
    return float(iou.mean()) if iou.size else float('nan')


def geometric_iou(confusion: np.ndarray, empty_index: int) -> float:
    """IoU of "occupied" (any class but ``empty_index``) vs empty.

    Args:
        confusion (np.ndarray): Counts, rows GT. Shape (C, C).
        empty_index (int): The empty (SurroundOcc) or free (Occ3D) class.

    Returns:
        float: Geometric IoU in [0, 1], or NaN when neither GT nor
        prediction has an occupied voxel.
    """
    confusion = np.asarray(confusion, dtype=np.float64)
    occupied = np.ones(confusion.shape[0], dtype=bool)
    occupied[empty_index] = False
    true_pos = confusion[occupied][:, occupied].sum()
    union = (confusion[occupied].sum() + confusion[:, occupied].sum() -
             true_pos)
    return float(true_pos / union) if union > 0 else float('nan')
