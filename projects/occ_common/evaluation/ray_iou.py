"""RayIoU: the ray-based occupancy metric of SparseOcc (Liu et al., ECCV
2024, Sec. 4 "RayIoU"), as its evaluation code defines it.

Instead of comparing voxels, RayIoU casts LiDAR-like rays from a few sensor
positions through the predicted and the ground-truth grid and compares what
each ray meets first: the class of the first occupied voxel and the depth
at which the ray leaves that voxel. The protocol, all of which this module
reproduces:

* **Origins**: the LiDAR positions of up to 8 key frames of the sample's
  scene, in the sample's ego frame (:mod:`.ray_origins`).
* **Rays** (:func:`.lidar_ray_directions`): 39 pitch angles x 360
  azimuths (1 degree) from every origin.
* **Casting** (:func:`.cast_rays`): Amanatides-Woo voxel traversal through
  the 0.4 m Occ3D grid; a voxel is occupied when its label is not free;
  a ray's depth is the distance from its origin to where it leaves the
  first occupied voxel; a ray that meets none hits nothing (free).
  Prediction and ground truth are cast the same way, with no camera mask.
* **Counting** (:func:`count_ray_hits`): rays whose ground truth hits
  nothing are dropped; on the others a ray counts for the ground truth of
  its GT class and for the prediction of its predicted class (so a
  predicted surface where the GT ray escapes is never counted), and is a
  true positive of class c at threshold tau when both classes are c and the
  depths differ by less than tau.
* **Scores** (:func:`ray_iou_from_counts`): counts are pooled over the
  whole set; IoU_c = TP / (GT + pred - TP); ``RayIoU@tau`` is the mean over
  classes (free excluded, ``others`` included, classes without rays left
  out), ``RayIoU`` the mean over tau in {1, 2, 4} m and the classes.

Origins and casting live in :mod:`.ray_origins` and :mod:`.ray_casting`
(which also names the two departures from SparseOcc's kernel, at rays
whose result RayIoU does not read or that never enter the grid); this
module counts and scores.
"""
import math
from typing import Dict, Optional, Sequence

import numpy as np

from ..datasets.nuscenes_classes import OCC3D_CLASS_NAMES
from .ray_casting import RayHits, cast_rays

#: Depth tolerances of RayIoU@1, @2 and @4, metres.
RAY_IOU_THRESHOLDS = (1.0, 2.0, 4.0)


def count_ray_hits(
    pred: RayHits,
    gt: RayHits,
    num_classes: int = len(OCC3D_CLASS_NAMES),
    free_index: int = len(OCC3D_CLASS_NAMES) - 1,
    thresholds: Sequence[float] = RAY_IOU_THRESHOLDS
) -> Dict[str, np.ndarray]:
    """Ray counts of one sample (or any set of rays), ready to be pooled.

    Rays whose ground truth hits nothing are dropped. Of the others, a ray
    counts for the GT of its GT class, for the prediction of its predicted
    class, and as a true positive of class c at threshold tau when both
    are c and ``|depth_pred - depth_gt| < tau`` (float32, as SparseOcc).
    Labels outside [0, C) (an ignore label) count for no class.

    Args:
        pred (RayHits): Cast through the prediction. Shape (N,).
        gt (RayHits): The same rays cast through the GT. Shape (N,).
        num_classes (int): C, free included. Defaults to 18.
        free_index (int): Label of free space. Defaults to 17.
        thresholds (Sequence[float]): Depth tolerances in metres.
            Defaults to (1, 2, 4).

    Returns:
        dict[str, np.ndarray]: int64 ``'gt'`` and ``'pred'`` Shape (C,)
        and ``'tp'`` Shape (K, C), K thresholds.
    """
    valid = gt.label != free_index
    gt_label = gt.label[valid].astype(np.int64)
    pred_label = pred.label[valid].astype(np.int64)
    error = np.abs(pred.depth[valid] - gt.depth[valid])
    same = gt_label == pred_label

    def per_class(labels: np.ndarray) -> np.ndarray:
        counted = labels[(labels >= 0) & (labels < num_classes)]
        return np.bincount(counted, minlength=num_classes)

    tp = np.stack([
        per_class(gt_label[same & (error < np.float32(tau))])
        for tau in thresholds
    ])
    return dict(gt=per_class(gt_label), pred=per_class(pred_label), tp=tp)


def ray_iou_from_counts(
    counts: Dict[str, np.ndarray],
    class_names: Sequence[str] = OCC3D_CLASS_NAMES,
    free_index: Optional[int] = None,
    thresholds: Sequence[float] = RAY_IOU_THRESHOLDS
) -> Dict[str, float]:
    """RayIoU in percent from pooled :func:`count_ray_hits` counts.

    Args:
        counts (dict[str, np.ndarray]): Summed counts.
        class_names (Sequence[str]): Names of the C labels. Defaults to
            Occ3D's.
        free_index (int, optional): Label of free space, left out of every
            mean. Defaults to the last.
        thresholds (Sequence[float]): The K tolerances of ``counts['tp']``.
            Defaults to (1, 2, 4).

    Returns:
        dict[str, float]: ``'RayIoU'`` (mean over thresholds and classes),
        ``'RayIoU@{tau}'`` (mean over classes), ``'RayIoU/{class}'`` (mean
        over thresholds) and ``'RayIoU@{tau}/{class}'``; a class with
        neither GT nor predicted rays is NaN and left out of the means.
    """
    num_classes = len(class_names)
    if free_index is None:
        free_index = num_classes - 1
    tp = np.asarray(counts['tp'], dtype=np.float64)
    union = counts['gt'] + counts['pred'] - tp
    with np.errstate(invalid='ignore', divide='ignore'):
        iou = np.where(union > 0, tp / np.maximum(union, 1), np.nan) * 100
    kept = [c for c in range(num_classes) if c != free_index]
    names = [f'RayIoU@{tau:g}' for tau in thresholds]
    metrics = {'RayIoU': _nanmean(iou[:, kept])}
    for k, name in enumerate(names):
        metrics[name] = _nanmean(iou[k, kept])
    for c in kept:
        metrics[f'RayIoU/{class_names[c]}'] = _nanmean(iou[:, c])
        for k, name in enumerate(names):
            metrics[f'{name}/{class_names[c]}'] = float(iou[k, c])
    return metrics


def _nanmean(values: np.ndarray) -> float:
    """Mean of the defined values; NaN (without a warning) if none is."""
    defined = values[~np.isnan(values)]
    return float(defined.mean()) if defined.size else math.nan


def compute_ray_iou(
    preds: Sequence[np.ndarray],
    gts: Sequence[np.ndarray],
    origins: Sequence[np.ndarray],
    class_names: Sequence[str] = OCC3D_CLASS_NAMES,
    free_index: Optional[int] = None,
    thresholds: Sequence[float] = RAY_IOU_THRESHOLDS
) -> Dict[str, float]:
    """RayIoU of a set of predictions, counts pooled over the whole set.

    Args:
        preds (Sequence[np.ndarray]): Predicted labels (numpy or torch),
            Shape (200, 200, 16) each.
        gts (Sequence[np.ndarray]): GT labels, Shape (200, 200, 16) each.
        origins (Sequence[np.ndarray]): Per sample, the ray origins in its
            ego frame (:func:`.ray_origins.scene_ray_origins`). Shape
            (T, 3) each.
        class_names (Sequence[str]): Label names. Defaults to Occ3D's.
        free_index (int, optional): Free label. Defaults to the last.
        thresholds (Sequence[float]): Depth tolerances, metres.
            Defaults to (1, 2, 4).

    Returns:
        dict[str, float]: See :func:`ray_iou_from_counts`.
    """
    if not len(preds) == len(gts) == len(origins):
        raise ValueError(f'compute_ray_iou: got {len(preds)} predictions, '
                         f'{len(gts)} GTs and {len(origins)} origin sets.')
    num_classes = len(class_names)
    if free_index is None:
        free_index = num_classes - 1
    total = dict(gt=np.zeros(num_classes, np.int64),
                 pred=np.zeros(num_classes, np.int64),
                 tp=np.zeros((len(thresholds), num_classes), np.int64))
    for pred, gt, origin in zip(preds, gts, origins):
        pred_hits, gt_hits = cast_rays([to_numpy(pred),
                                        to_numpy(gt)],
                                       to_numpy(origin),
                                       free_index=free_index)
        counts = count_ray_hits(pred_hits, gt_hits, num_classes, free_index,
                                thresholds)
        for key in total:
            total[key] += counts[key]
    return ray_iou_from_counts(total, class_names, free_index, thresholds)


def to_numpy(value) -> np.ndarray:
    """A numpy array from an array, a (device) tensor or a list."""
    if hasattr(value, 'detach'):
        value = value.detach().cpu().numpy()
    return np.asarray(value)
