"""IoU / mIoU of semantic occupancy under SurroundOcc or Occ3D rules."""
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch
from mmdet3d.registry import METRICS
from mmengine.evaluator import BaseMetric
from mmengine.logging import print_log

from ..datasets.nuscenes_classes import OCC3D_CLASS_NAMES
from ..datasets.occ_formats import SURROUNDOCC_CLASS_NAMES
from .occupancy_confusion import (confusion_matrix, geometric_iou, mean_iou,
                                  per_class_iou, write_confusion_csv)
from .occupancy_export import write_prediction, zip_folder_files

# The label tables live once, in datasets/, so that the metric cannot
# disagree with the loaders on an index.
#: SurroundOcc labels: 0 is empty, 1-16 the nuScenes-lidarseg classes.
SURROUNDOCC_CLASSES = SURROUNDOCC_CLASS_NAMES
#: Occ3D-nuScenes labels: 0 is ``others``, 1-16 as above, 17 is ``free``.
OCC3D_CLASSES = OCC3D_CLASS_NAMES


def _as_tensor(value) -> torch.Tensor:
    """A tensor from a tensor, numpy array or nested list, without copy."""
    return value if torch.is_tensor(value) else torch.as_tensor(
        np.asarray(value))


@METRICS.register_module()
class OccupancyMetric(BaseMetric):
    """Semantic occupancy IoU / mIoU, exact to the benchmarks' conventions.

    Counts are accumulated over the whole dataset in one confusion matrix
    and the IoUs computed once at the end (not a mean of per-sample IoUs).
    Voxels labelled ``ignore_index`` in the GT are never counted.

    - ``convention='surroundocc'`` (Wei et al., SurroundOcc, ICCV 2023):
      class 0 is empty and there is no visibility mask; ``IoU`` is the
      geometric IoU of occupied (labels 1-16) vs empty, ``mIoU`` the mean
      IoU of classes 1-16.
    - ``convention='occ3d'`` (Tian et al., Occ3D, NeurIPS 2023): 18 classes
      with 17 = free; with ``use_camera_mask`` only voxels whose
      ``mask_camera`` is set count; ``mIoU`` is the mean IoU of classes
      0-16 (``others`` included, free excluded), where a voxel of free
      predicted as c (or of c predicted as free) is still a false positive
      (false negative) of c; ``IoU`` is the geometric IoU of non-free vs
      free.

    In both, a class that occurs in neither GT nor prediction has no IoU
    (NaN in its key) and is left out of the mean, as Occ3D's ``nanmean``.

    With ``class_voxel_counts`` the metrics also hold
    ``'gt_voxels/{class}'``: the number of counted GT voxels of each class
    (after the ignore label and the camera mask), so that a reader can
    tell a class the model fails from one the split hardly contains; the
    printed table then has a column of them.

    Optional breakdowns: ``subsets`` gives ``'{name}/IoU'`` and
    ``'{name}/mIoU'`` over the samples whose ``'is_{name}'`` flag is true
    (OccCylindrical Tables II-III: rainy, night); ``distance_ranges`` gives
    ``'dist_{lo}-{hi}m/IoU'`` and ``/mIoU`` over the voxels whose centre
    lies at a horizontal distance d from the ego with lo <= d < hi
    (SDG-OCC Fig. 7). The ego is the origin of ``point_cloud_range``.

    Each data sample given to :meth:`process` is a dict with ``'pred_occ'``
    and ``'gt_occ'`` (integer arrays / tensors, Shape (X, Y, Z)), for
    Occ3D with the camera mask ``'mask_camera'`` (bool, Shape (X, Y, Z)),
    the subset flags, and ``'sample_idx'`` to name the sample in errors.
    Only confusion matrices are stored per sample.

    With ``confusion_file`` the dataset's confusion matrix (all counted
    voxels, rows GT, columns prediction) is also written there as CSV
    (:func:`.write_confusion_csv`), to show where a weak class's voxels
    go, e.g. ``tools/test.py CONFIG CKPT --cfg-options
    test_evaluator.confusion_file=work_dirs/confusion.csv``.

    With ``submission_prefix`` every prediction is also written there, in
    the layout of its convention (:mod:`.occupancy_export`: Occ3D
    ``<token>.npz`` files and their ``.zip``, SurroundOcc ``.npy`` rows),
    by the rank that predicted it; with ``format_only`` (mmdet3d's
    semantics, ``tools/test.py --format-only``) nothing is scored, no
    ``gt_occ`` is needed (a split without labels runs) and the metric
    returns no keys.

    Args:
        convention (str): ``'surroundocc'`` or ``'occ3d'``.
            Defaults to 'surroundocc'.
        class_names (Sequence[str], optional): Names of the C classes, in
            label order. Defaults to :data:`SURROUNDOCC_CLASSES` or
            :data:`OCC3D_CLASSES`.
        use_camera_mask (bool): Occ3D only: count only voxels with
            ``mask_camera``. SurroundOcc has no mask and ignores this.
            Defaults to True.
        subsets (Sequence[str], optional): Subset names, e.g.
            ``('rainy', 'night')``. Defaults to None.
        distance_ranges (Sequence[tuple], optional): ``(lo, hi)`` metres,
            e.g. ``[(0, 20), (20, 30), (30, 40)]``. Defaults to None.
        voxel_size (Sequence[float], optional): Voxel size (x, y, z) in
            metres; required with ``distance_ranges``. Defaults to None.
        point_cloud_range (Sequence[float], optional): Grid extent
            ``(x0, y0, z0, x1, y1, z1)`` in ego coordinates; required with
            ``distance_ranges``. Defaults to None.
        ignore_index (int): GT label of unannotated voxels. Defaults to 255.
        class_voxel_counts (bool): Add the GT voxel count of every class to
            the metrics and the table. Defaults to False.
        format_only (bool): Write the predictions, score nothing. Needs
            ``submission_prefix``. Defaults to False.
        submission_prefix (str, optional): Folder of the prediction files.
            Defaults to None (none written).
        confusion_file (str, optional): CSV file for the confusion
            matrix. Defaults to None (none written).
        collect_device (str): Device to gather results on. Defaults to
            'cpu'.
        prefix (str, optional): Key prefix. Defaults to ``'occ'``.
        collect_dir (str, optional): Directory for CPU gathering.
            Defaults to None.
    """

    default_prefix = 'occ'

    def __init__(self,
                 convention: str = 'surroundocc',
                 class_names: Optional[Sequence[str]] = None,
                 use_camera_mask: bool = True,
                 subsets: Optional[Sequence[str]] = None,
                 distance_ranges: Optional[Sequence[Tuple[float,
                                                          float]]] = None,
                 voxel_size: Optional[Sequence[float]] = None,
                 point_cloud_range: Optional[Sequence[float]] = None,
                 ignore_index: int = 255,
                 class_voxel_counts: bool = False,
                 format_only: bool = False,
                 submission_prefix: Optional[str] = None,
                 confusion_file: Optional[str] = None,
                 collect_device: str = 'cpu',
                 prefix: Optional[str] = None,
                 collect_dir: Optional[str] = None) -> None:
        super().__init__(
            collect_device=collect_device,
            prefix=prefix,
            collect_dir=collect_dir)
        if convention not in ('surroundocc', 'occ3d'):
            raise ValueError("OccupancyMetric: expected convention "
                             f"'surroundocc' or 'occ3d', got {convention!r}.")
        self.convention = convention
        default = (SURROUNDOCC_CLASSES
                   if convention == 'surroundocc' else OCC3D_CLASSES)
        self.class_names = tuple(class_names or default)
        self.num_classes = len(self.class_names)
        if self.num_classes < 2:
            raise ValueError('OccupancyMetric: expected at least 2 classes, '
                             f'got {self.class_names}.')
        # SurroundOcc puts empty first, Occ3D puts free last.
        self.empty_index = (0 if convention == 'surroundocc' else
                            self.num_classes - 1)
        self.semantic_classes = [
            c for c in range(self.num_classes) if c != self.empty_index
        ]
        self.use_camera_mask = convention == 'occ3d' and use_camera_mask
        if format_only and submission_prefix is None:
            raise ValueError('OccupancyMetric: format_only=True writes the '
                             'predictions to submission_prefix; give one.')
        self.format_only = format_only
        self.submission_prefix = submission_prefix
        self.confusion_file = confusion_file
        self.subsets = tuple(subsets or ())
        self.ignore_index = ignore_index
        self.class_voxel_counts = bool(class_voxel_counts)
        self.distance_ranges = self._check_ranges(distance_ranges)
        self._occ_shape: Optional[Tuple[int, int, int]] = None
        self._range_masks: Dict[str, torch.Tensor] = {}
        if self.distance_ranges:
            if voxel_size is None or point_cloud_range is None:
                raise ValueError('OccupancyMetric: distance_ranges needs '
                                 'voxel_size and point_cloud_range.')
            dist, self._occ_shape = self._horizontal_distance(
                voxel_size, point_cloud_range)
            # One (X, Y) column mask per range, built once; copies per
            # device are cached by _column_masks.
            self._range_masks['cpu'] = torch.from_numpy(
                np.stack([(dist >= lo) & (dist < hi)
                          for lo, hi in self.distance_ranges]))

    @staticmethod
    def _check_ranges(ranges) -> List[Tuple[float, float]]:
        """Validate ``distance_ranges`` as (lo, hi) pairs, 0 <= lo < hi."""
        checked = []
        for pair in ranges or ():
            if len(pair) != 2 or not 0 <= pair[0] < pair[1]:
                raise ValueError('OccupancyMetric: expected distance ranges '
                                 f'(lo, hi) with 0 <= lo < hi, got {pair!r}.')
            checked.append((float(pair[0]), float(pair[1])))
        return checked

    @staticmethod
    def _horizontal_distance(
            voxel_size: Sequence[float], point_cloud_range: Sequence[float]
    ) -> Tuple[np.ndarray, Tuple[int, int, int]]:
        """Distance of each voxel-centre column from the ego.

        Returns:
            tuple[np.ndarray, tuple]: Metres, Shape (X, Y), and the grid
            shape (X, Y, Z) implied by the range and voxel size.
        """
        if len(voxel_size) != 3 or len(point_cloud_range) != 6:
            raise ValueError('OccupancyMetric: expected voxel_size (x, y, z)'
                             ' and point_cloud_range (x0, y0, z0, x1, y1, '
                             f'z1), got {voxel_size!r}, '
                             f'{point_cloud_range!r}.')
        size = np.asarray(voxel_size, dtype=np.float64)
        low = np.asarray(point_cloud_range[:3], dtype=np.float64)
        high = np.asarray(point_cloud_range[3:], dtype=np.float64)
        shape = np.round((high - low) / size).astype(int)
        centres = [low[i] + (np.arange(shape[i]) + 0.5) * size[i]
                   for i in range(2)]
        dist = np.hypot(centres[0][:, None], centres[1][None, :])
        return dist, tuple(int(n) for n in shape)

    def _column_masks(self, device: torch.device) -> torch.Tensor:
        """Range masks on ``device``. Shape (R, X, Y, 1)."""
        key = str(device)
        if key not in self._range_masks:
            self._range_masks[key] = self._range_masks['cpu'].to(device)
        return self._range_masks[key][..., None]

    def _range_keys(self) -> List[str]:
        """Key prefix of each distance range, e.g. ``'dist_0-20m'``."""
        return [f'dist_{lo:g}-{hi:g}m' for lo, hi in self.distance_ranges]

    def process(self, data_batch, data_samples: Sequence[dict]) -> None:
        """Store the confusion matrices of a batch.

        Args:
            data_batch: Unused; the predictions carry everything.
            data_samples (Sequence[dict]): See the class docstring.
        """
        for sample in data_samples:
            result = {} if self.format_only else self._sample_result(sample)
            if self.submission_prefix is not None:
                result['file'] = self._write(sample)
            self.results.append(result)

    def _write(self, sample: dict) -> str:
        """Write the sample's prediction file; returns its name."""
        name = sample.get('sample_idx', f'#{len(self.results)}')
        pred = self._labels(sample, 'pred_occ', name)
        self._check_pred(pred, name)
        return write_prediction(self.submission_prefix, self.convention,
                                sample, pred, self.empty_index)

    def _sample_result(self, sample: dict) -> dict:
        """Validate one sample and reduce it to confusion matrices."""
        name = sample.get('sample_idx', f'#{len(self.results)}')
        pred = self._labels(sample, 'pred_occ', name)
        # Count where the prediction lives (the GPU during validation).
        gt = self._labels(sample, 'gt_occ', name).to(pred.device)
        if pred.shape != gt.shape:
            raise ValueError(f'OccupancyMetric: sample {name}: pred_occ '
                             f'{tuple(pred.shape)} and gt_occ '
                             f'{tuple(gt.shape)} differ.')
        counted = gt != self.ignore_index
        bad_gt = counted & ((gt < 0) | (gt >= self.num_classes))
        if bool(bad_gt.any()):
            raise ValueError(
                f'OccupancyMetric: sample {name}: gt_occ has labels '
                f'{torch.unique(gt[bad_gt]).tolist()[:10]} outside [0, '
                f'{self.num_classes}) and not {self.ignore_index}.')
        self._check_pred(pred, name)
        if self.use_camera_mask:
            if sample.get('mask_camera') is None:
                raise ValueError(f'OccupancyMetric: sample {name} has no '
                                 'mask_camera (occ3d, use_camera_mask=True).')
            mask = _as_tensor(sample['mask_camera']).to(gt.device)
            if mask.shape != gt.shape:
                raise ValueError(
                    f'OccupancyMetric: sample {name}: mask_camera '
                    f'{tuple(mask.shape)} and gt_occ {tuple(gt.shape)} '
                    'differ.')
            counted = counted & mask.bool()
        result = {'confusion': self._confusion(gt, pred, counted)}
        if self.subsets:
            result['subsets'] = tuple(
                s for s in self.subsets if self._flag(sample, s, name))
        if self.distance_ranges:
            if tuple(gt.shape) != self._occ_shape:
                raise ValueError(
                    f'OccupancyMetric: sample {name}: grid '
                    f'{tuple(gt.shape)} does not match point_cloud_range / '
                    f'voxel_size {self._occ_shape}.')
            result['distance_confusion'] = np.stack([
                self._confusion(gt, pred, counted & in_range)
                for in_range in self._column_masks(gt.device)
            ])
        return result

    def _check_pred(self, pred: torch.Tensor, name) -> None:
        """Refuse predicted labels outside the classes."""
        # A model never predicts "ignore", so 255 is an error here too.
        bad = (pred < 0) | (pred >= self.num_classes)
        if bool(bad.any()):
            raise ValueError(
                f'OccupancyMetric: sample {name}: pred_occ has labels '
                f'{torch.unique(pred[bad]).tolist()[:10]} outside [0, '
                f'{self.num_classes}).')

    def _confusion(self, gt, pred, counted) -> np.ndarray:
        """Confusion matrix of the counted voxels as a small numpy array."""
        return confusion_matrix(gt[counted], pred[counted],
                                self.num_classes).cpu().numpy()

    @staticmethod
    def _labels(sample: dict, key: str, name) -> torch.Tensor:
        """Fetch an integer label grid as a tensor."""
        if sample.get(key) is None:
            raise ValueError(f'OccupancyMetric: sample {name} has no {key}.')
        value = _as_tensor(sample[key])
        if value.dtype.is_floating_point or value.dtype == torch.bool:
            raise ValueError(f'OccupancyMetric: sample {name}: expected '
                             f'integer {key}, got {value.dtype}.')
        if value.dim() != 3:
            raise ValueError(f'OccupancyMetric: sample {name}: expected {key}'
                             f' of shape (X, Y, Z), got {tuple(value.shape)}.')
        return value.long()

    @staticmethod
    def _flag(sample: dict, subset: str, name) -> bool:
        """Subset flag ``'is_{subset}'``; missing flags are an error."""
        key = f'is_{subset}'
        if key not in sample:
            raise ValueError(f'OccupancyMetric: sample {name} has no {key!r}'
                             f' flag, needed for subset {subset!r}.')
        return bool(sample[key])

    def compute_metrics(self, results: list) -> Dict[str, float]:
        """Sum the confusion matrices and compute the percentages.

        Args:
            results (list[dict]): :meth:`process` outputs of all ranks.

        Returns:
            dict[str, float]: ``'IoU'``, ``'mIoU'``, one key per class name,
            and the subset / distance keys when enabled, in percent; NaN
            where undefined (e.g. a subset without samples). Nothing with
            ``format_only``.
        """
        if self.submission_prefix is not None:
            self._finish_files([r['file'] for r in results])
        if self.format_only:
            return {}
        size = (self.num_classes, self.num_classes)
        total = sum((r['confusion'] for r in results), np.zeros(size, int))
        columns = {'all': total}
        if self.confusion_file is not None:
            write_confusion_csv(self.confusion_file, total, self.class_names)
            print_log(f'OccupancyMetric: wrote the confusion matrix to '
                      f'{self.confusion_file}', logger='current')
        metrics = self._scores(total)
        metrics.update({
            name: float(iou) * 100
            for name, iou in zip(self.class_names, per_class_iou(total))
        })
        if self.class_voxel_counts:
            # Floats: mmengine's message hub turns an int into numpy's
            # int64, which its json log drops (written as null).
            metrics.update({
                f'gt_voxels/{name}': float(count)
                for name, count in zip(self.class_names, total.sum(1))
            })
        for subset in self.subsets:
            confusion = sum((r['confusion']
                             for r in results if subset in r['subsets']),
                            np.zeros(size, int))
            columns[subset] = confusion
            metrics.update({
                f'{subset}/{k}': v
                for k, v in self._scores(confusion).items()
            })
        for i, key in enumerate(self._range_keys()):
            confusion = sum((r['distance_confusion'][i] for r in results),
                            np.zeros(size, int))
            columns[key] = confusion
            metrics.update({
                f'{key}/{k}': v
                for k, v in self._scores(confusion).items()
            })
        print_log(self._table(columns), logger='current')
        return metrics

    def _finish_files(self, files: List[str]) -> None:
        """Zip an Occ3D submission and say where the files are."""
        where = f'{len(set(files))} {self.convention} prediction files in ' \
            f'{self.submission_prefix}'
        if self.convention == 'occ3d':
            where += (' and the zip the Occ3D server takes: ' +
                      zip_folder_files(self.submission_prefix, set(files)))
        print_log(f'OccupancyMetric: wrote {where}', logger='current')

    def _scores(self, confusion: np.ndarray) -> Dict[str, float]:
        """Geometric IoU and mIoU in percent."""
        return {
            'IoU': geometric_iou(confusion, self.empty_index) * 100,
            'mIoU': mean_iou(confusion, self.semantic_classes) * 100,
        }

    def _table(self, columns: Dict[str, np.ndarray]) -> str:
        """Per-class IoU table, one column per group of voxels."""
        width = max(len(n) for n in self.class_names + ('mIoU', )) + 2
        names = list(columns)
        header = 'class'.ljust(width) + ''.join(n.rjust(14) for n in names)
        ious = {n: per_class_iou(c) * 100 for n, c in columns.items()}
        scores = {n: self._scores(c) for n, c in columns.items()}
        counts = columns['all'].sum(1) if self.class_voxel_counts else None
        if counts is not None:
            header += 'GT voxels'.rjust(14)
        lines = [f'Occupancy ({self.convention}) per-class IoU (%):', header]
        for c, class_name in enumerate(self.class_names):
            suffix = ' *' if c == self.empty_index else ''
            lines.append((class_name + suffix).ljust(width) +
                         ''.join(f'{ious[n][c]:14.2f}' for n in names) +
                         ('' if counts is None else f'{counts[c]:14d}'))
        for key in ('IoU', 'mIoU'):
            lines.append(
                key.ljust(width) +
                ''.join(f'{scores[n][key]:14.2f}' for n in names))
        lines.append('* not in the mIoU; IoU is occupied vs '
                     f'{self.class_names[self.empty_index]}.')
        return '\n'.join(lines)
