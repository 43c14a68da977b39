"""How close one set of occupancy labels is to a reference set.

Made to score generated labels (``tools/dataset_converters/
generate_occupancy.py``) against the synthetic world's exact ones, but
any two label folders of the same samples compare (e.g. generated labels
against Occ3D's own on real nuScenes). Both are read with the datasets'
own loader (:class:`..transforms.loading.LoadOccupancyGT`), so what is
scored is what training would see.

:class:`LabelQuality` sums confusion matrices over the samples:

* Occ3D (18 labels, 17 free) inside the reference's ``mask_lidar``,
  inside its ``mask_camera`` and over the whole grid; ``mIoU`` over
  labels 0..16 and the geometric ``IoU`` of non-free vs free, as
  :class:`.OccupancyMetric` scores a prediction;
* SurroundOcc (17 labels, 0 empty) over the whole grid, the reference's
  ``noise`` voxels ignored; a generated ``noise`` voxel (an occupied
  voxel without a class) counts as empty, as models trained on such
  labels never learn it;
* the agreement of the generated masks with the reference's: IoU, and
  the shares of the reference mask covered (recall) and of the generated
  mask inside the reference (precision).
"""
from typing import Dict

import numpy as np
import torch

from ..datasets.nuscenes_classes import OCC3D_CLASS_NAMES, OCC3D_FREE_LABEL
from ..datasets.occ_formats import IGNORE_INDEX, SURROUNDOCC_CLASS_NAMES
from ..transforms.loading import LoadOccupancyGT
from .occupancy_confusion import (confusion_matrix, geometric_iou, mean_iou,
                                  per_class_iou)

#: Regions of the Occ3D grid scored: the reference's masks and all.
OCC3D_REGIONS = ('lidar_mask', 'camera_mask', 'grid')


def _confusion(gt: np.ndarray, pred: np.ndarray, num: int) -> np.ndarray:
    return confusion_matrix(torch.from_numpy(gt.astype(np.int64)),
                            torch.from_numpy(pred.astype(np.int64)),
                            num).numpy()


def _scores(confusion: np.ndarray, classes, empty: int) -> dict:
    iou = per_class_iou(confusion)
    return dict(IoU=100 * geometric_iou(confusion, empty),
                mIoU=100 * mean_iou(confusion, classes),
                per_class=(100 * iou).tolist())


class LabelQuality:
    """Generated labels against reference labels, summed over samples."""

    def __init__(self) -> None:
        self.loaders = {fmt: LoadOccupancyGT(occ_format=fmt)
                        for fmt in ('occ3d', 'surroundocc')}
        num = len(OCC3D_CLASS_NAMES)
        self.occ3d = {r: np.zeros((num, num), np.int64)
                      for r in OCC3D_REGIONS}
        num = len(SURROUNDOCC_CLASS_NAMES)
        self.surroundocc = np.zeros((num, num), np.int64)
        # Per mask: reference, generated and both voxel counts.
        self.masks = {m: np.zeros(3, np.int64)
                      for m in ('mask_lidar', 'mask_camera')}
        self.samples = dict(occ3d=0, surroundocc=0)

    def _load(self, fmt: str, path: str) -> dict:
        return self.loaders[fmt](dict(occ_path=path, occ_format=fmt))

    def add_occ3d(self, reference_path: str, generated_path: str) -> None:
        """Add one key frame's Occ3D ``labels.npz`` pair."""
        ref = self._load('occ3d', reference_path)
        gen = self._load('occ3d', generated_path)
        regions = dict(lidar_mask=ref['mask_lidar'],
                       camera_mask=ref['mask_camera'],
                       grid=np.ones_like(ref['mask_lidar']))
        for name, region in regions.items():
            self.occ3d[name] += _confusion(
                ref['gt_occ'][region], gen['gt_occ'][region],
                len(OCC3D_CLASS_NAMES))
        for key, counts in self.masks.items():
            counts += [ref[key].sum(), gen[key].sum(),
                       (ref[key] & gen[key]).sum()]
        self.samples['occ3d'] += 1

    def add_surroundocc(self, reference_path: str,
                        generated_path: str) -> None:
        """Add one key frame's SurroundOcc ``.npy`` pair."""
        ref = self._load('surroundocc', reference_path)['gt_occ']
        gen = self._load('surroundocc', generated_path)['gt_occ']
        counted = ref != IGNORE_INDEX
        gen = np.where(gen == IGNORE_INDEX, 0, gen)
        self.surroundocc += _confusion(ref[counted], gen[counted],
                                       len(SURROUNDOCC_CLASS_NAMES))
        self.samples['surroundocc'] += 1

    def summary(self) -> Dict[str, object]:
        """The scores, in %.

        Returns:
            dict: ``occ3d`` (per region ``IoU``, ``mIoU``, ``per_class``
            over :data:`..datasets.nuscenes_classes.OCC3D_CLASS_NAMES`),
            ``surroundocc`` (the same over
            :data:`..datasets.occ_formats.SURROUNDOCC_CLASS_NAMES`),
            ``masks`` (per mask ``IoU``, ``recall``, ``precision``) and
            ``samples``.
        """
        occ3d = {region: _scores(c, range(OCC3D_FREE_LABEL),
                                 OCC3D_FREE_LABEL)
                 for region, c in self.occ3d.items()}
        surroundocc = _scores(self.surroundocc,
                              range(1, len(SURROUNDOCC_CLASS_NAMES)), 0)
        masks = {}
        for key, (ref, gen, both) in self.masks.items():
            union = ref + gen - both
            masks[key] = dict(
                IoU=100 * both / union if union else float('nan'),
                recall=100 * both / ref if ref else float('nan'),
                precision=100 * both / gen if gen else float('nan'))
        return dict(occ3d=occ3d, surroundocc=surroundocc, masks=masks,
                    samples=dict(self.samples))
