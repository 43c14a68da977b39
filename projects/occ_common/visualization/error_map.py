"""Voxel-wise error map of a prediction against its ground truth.

Every voxel the metric counts (GT not ``ignore_index``, inside the camera
mask if one is given) gets one code, following the confusion matrix of
:class:`~projects.occ_common.evaluation.OccupancyMetric`:

- 0: correct (same label in prediction and GT);
- 1: false positive: GT empty, prediction a class;
- 2: false negative: GT a class, prediction empty;
- 3: wrong class: both a class, not the same one.

Voxels that are not counted are 0. The codes index
:data:`~.palette.ERROR_NAMES` / :data:`~.palette.ERROR_PALETTE`, so the
error grid renders with the same views as a label grid (``empty_label=0``).
"""
from typing import Dict, Optional

import numpy as np

from .label_grid import occupied_voxels
from .palette import ERROR_NAMES

CORRECT, FALSE_POSITIVE, FALSE_NEGATIVE, WRONG_CLASS = range(4)


def occupancy_errors(pred: np.ndarray,
                     gt: np.ndarray,
                     num_classes: int,
                     empty_label: int,
                     ignore_index: int = 255,
                     mask: Optional[np.ndarray] = None) -> np.ndarray:
    """Error code of every voxel.

    Args:
        pred (np.ndarray): Predicted labels in ``[0, num_classes)``.
            Shape (X, Y, Z), int.
        gt (np.ndarray): GT labels, ``ignore_index`` for unannotated
            voxels. Shape (X, Y, Z), int.
        num_classes (int): Number of classes ``C``.
        empty_label (int): Label of empty space.
        ignore_index (int): GT label never counted. Defaults to 255.
        mask (np.ndarray, optional): Voxels that count, Shape (X, Y, Z).
            Defaults to None (all).

    Returns:
        np.ndarray: Codes 0-3 (module docstring). Shape (X, Y, Z), uint8.

    Raises:
        ValueError: If the shapes differ or a label is out of range (a
            prediction may not be ``ignore_index`` either).
    """
    if pred.shape != gt.shape:
        raise ValueError(f'pred_occ {pred.shape} and gt_occ {gt.shape} '
                         'differ in shape.')
    bad = (pred < 0) | (pred >= num_classes)
    if bad.any():
        raise ValueError(
            f'pred_occ: labels {np.unique(pred[bad])[:10].tolist()} are '
            f'outside [0, {num_classes}).')
    gt_occupied = occupied_voxels(gt, num_classes, empty_label,
                                  ignore_index, None, 'gt_occ')
    counted = gt != ignore_index
    if mask is not None:
        counted &= mask
    pred_occupied = pred != empty_label
    codes = np.zeros(gt.shape, dtype=np.uint8)
    codes[counted & pred_occupied & ~gt_occupied] = FALSE_POSITIVE
    codes[counted & ~pred_occupied & gt_occupied] = FALSE_NEGATIVE
    codes[counted & pred_occupied & gt_occupied & (pred != gt)] = WRONG_CLASS
    return codes


def error_counts(codes: np.ndarray) -> Dict[str, int]:
    """Number of voxels with each error code.

    Args:
        codes (np.ndarray): Output of :func:`occupancy_errors`.

    Returns:
        dict[str, int]: ``{'false positive': n1, 'false negative': n2,
        'wrong class': n3}``.
    """
    counts = np.bincount(codes.ravel(), minlength=len(ERROR_NAMES))
    return {
        name: int(counts[code])
        for code, name in enumerate(ERROR_NAMES) if code != CORRECT
    }
