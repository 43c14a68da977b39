"""Confusion matrices and IoU scores of semantic occupancy grids.

Everything the occupancy metric reports is derived from a C x C confusion
matrix (rows: ground truth, columns: prediction) accumulated over the
dataset, so per-rank results reduce by summation.
"""
import csv
import os
from typing import List, Sequence, Tuple

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


#: First cell of a confusion CSV's header row (rows GT, columns prediction).
CONFUSION_CSV_CORNER = 'gt \\ pred'


def write_confusion_csv(path: str, confusion: np.ndarray,
                        class_names: Sequence[str]) -> None:
    """Write a confusion matrix as CSV, class names on both axes.

    The header row is ``gt \\ pred`` and the C class names; each further
    row is a GT class name and its C integer counts, so that a reader (a
    spreadsheet, ``numpy.loadtxt``, :func:`read_confusion_csv`) sees where
    each class's voxels went. The parent folder is made if needed.

    Args:
        path (str): File to write.
        confusion (np.ndarray): Counts, rows GT. Shape (C, C).
        class_names (Sequence[str]): The C names, in label order.
    """
    confusion = np.asarray(confusion)
    names = [str(n) for n in class_names]
    if confusion.shape != (len(names), len(names)):
        raise ValueError(f'write_confusion_csv: {path}: expected a '
                         f'({len(names)}, {len(names)}) matrix for classes '
                         f'{names}, got shape {confusion.shape}.')
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, 'w', newline='') as f:
        writer = csv.writer(f)
        writer.writerow([CONFUSION_CSV_CORNER] + names)
        for name, row in zip(names, confusion):
            writer.writerow([name] + [int(v) for v in row])


def read_confusion_csv(path: str) -> Tuple[List[str], np.ndarray]:
    """Read a matrix written by :func:`write_confusion_csv`.

    Args:
        path (str): The CSV file.

    Returns:
        tuple[list[str], np.ndarray]: The C class names and the int64
        counts, rows GT. Shape (C, C).
    """
    with open(path, newline='') as f:
        rows = list(csv.reader(f))
    if not rows or rows[0][:1] != [CONFUSION_CSV_CORNER]:
        raise ValueError(f'read_confusion_csv: {path}: expected a header row'
                         f' starting with {CONFUSION_CSV_CORNER!r}.')
    names = rows[0][1:]
    body = rows[1:]
    if [r[:1] for r in body] != [[n] for n in names] or any(
            len(r) != len(names) + 1 for r in body):
        raise ValueError(f'read_confusion_csv: {path}: expected one row per '
                         f'class {names}, in header order, with '
                         f'{len(names)} counts each.')
    try:
        counts = np.array([[int(v) for v in r[1:]] for r in body],
                          dtype=np.int64).reshape(len(names), len(names))
    except ValueError as err:
        raise ValueError(f'read_confusion_csv: {path}: a count is not an '
                         f'integer ({err}).') from None
    return names, counts


def largest_confusions(confusion: np.ndarray, gt_class: int,
                       k: int = 2) -> List[Tuple[int, float]]:
    """The ``k`` other classes that take most of a class's GT voxels.

    Args:
        confusion (np.ndarray): Counts, rows GT. Shape (C, C).
        gt_class (int): The class whose row is read.
        k (int): How many classes to return. Defaults to 2.

    Returns:
        list[tuple[int, float]]: ``(predicted class, share of gt_class's
        GT voxels)``, largest share first, ties to the lower label; classes
        that take none are left out, so the list may be shorter than k.
    """
    row = np.asarray(confusion, dtype=np.float64)[gt_class]
    total = row.sum()
    if total == 0:
        return []
    order = sorted((c for c in range(row.size) if c != gt_class),
                   key=lambda c: (-row[c], c))
    return [(c, float(row[c] / total)) for c in order[:k] if row[c] > 0]
