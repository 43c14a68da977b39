"""Expected calibration error of the voxel class probabilities."""
from typing import Dict, Optional, Sequence

import numpy as np
import torch
from mmdet3d.registry import METRICS
from mmengine.evaluator import BaseMetric

#: Rows of a per-sample result: voxels, summed confidence, summed
#: correctness, per confidence bin.
_COUNT, _CONFIDENCE, _CORRECT = range(3)


def calibration_bins(probs: torch.Tensor, gt: torch.Tensor,
                     counted: torch.Tensor, num_bins: int) -> np.ndarray:
    """Per-bin voxel counts, summed confidence and summed correctness.

    A voxel's confidence is its largest class probability and it is
    correct when that class is the GT's; it falls in bin
    ``min(floor(confidence * num_bins), num_bins - 1)`` of equal-width bins
    over [0, 1].

    Args:
        probs (Tensor): Class probabilities. Shape (K, X, Y, Z).
        gt (Tensor): Labels. Shape (X, Y, Z).
        counted (Tensor): Voxels to count, bool. Shape (X, Y, Z).
        num_bins (int): Confidence bins.

    Returns:
        np.ndarray: float64. Shape (3, num_bins): count, confidence sum,
        correct sum.
    """
    confidence, label = probs.max(dim=0)
    confidence, label, gt = confidence[counted], label[counted], gt[counted]
    bins = (confidence * num_bins).long().clamp_(0, num_bins - 1)
    out = torch.stack([
        torch.bincount(bins, minlength=num_bins).double(),
        torch.bincount(bins, confidence.double(), minlength=num_bins),
        torch.bincount(bins, (label == gt).double(), minlength=num_bins),
    ])
    return out.cpu().numpy()


def expected_calibration_error(bins: np.ndarray) -> Dict[str, float]:
    """ECE (Guo et al., ICML 2017) of summed :func:`calibration_bins`.

    ``ECE = sum_b (n_b / N) |acc_b - conf_b|``, with ``acc_b`` and
    ``conf_b`` the mean correctness and confidence of bin b.

    Args:
        bins (np.ndarray): Shape (3, B).

    Returns:
        dict[str, float]: ``ECE``, ``confidence`` (mean) and ``accuracy``
        in percent; NaN without voxels.
    """
    total = bins[_COUNT].sum()
    if total == 0:
        return dict(ECE=float('nan'), confidence=float('nan'),
                    accuracy=float('nan'))
    gap = np.abs(bins[_CORRECT] - bins[_CONFIDENCE]).sum() / total
    return dict(ECE=100.0 * gap,
                confidence=100.0 * bins[_CONFIDENCE].sum() / total,
                accuracy=100.0 * bins[_CORRECT].sum() / total)


@METRICS.register_module()
class OccupancyCalibrationMetric(BaseMetric):
    """How well a model's voxel class probabilities match its accuracy.

    Expected calibration error (ECE, Guo et al., ICML 2017) over the voxels
    that :class:`~.OccupancyMetric` counts (GT not ``ignore_index``, inside
    ``mask_camera`` with ``use_camera_mask``): a model that knows when its
    sensors fail has a low ECE under corruption too. With ``empty_index``
    also ``nonempty/ECE``, over the voxels that are occupied in the GT or
    the prediction (the whole-grid ECE is dominated by confident empty
    space).

    Each data sample given to :meth:`process` holds ``pred_logits``
    (float, Shape (K, X, Y, Z), softmax over K), ``gt_occ`` (Shape (X, Y,
    Z)) and, with ``use_camera_mask``, ``mask_camera``. Only the per-bin
    sums are kept per sample.

    Args:
        num_bins (int): Equal-width confidence bins. Defaults to 15 (Guo et
            al.'s).
        empty_index (int, optional): Label of empty space. Defaults to None
            (no ``nonempty/`` keys).
        use_camera_mask (bool): Count only ``mask_camera`` voxels.
            Defaults to False.
        ignore_index (int): GT label of uncounted voxels. Defaults to 255.
        collect_device (str): Device to gather results on. Defaults to
            'cpu'.
        prefix (str, optional): Key prefix. Defaults to ``'calib'``.
    """

    default_prefix = 'calib'

    def __init__(self,
                 num_bins: int = 15,
                 empty_index: Optional[int] = None,
                 use_camera_mask: bool = False,
                 ignore_index: int = 255,
                 collect_device: str = 'cpu',
                 prefix: Optional[str] = None) -> None:
        super().__init__(collect_device=collect_device, prefix=prefix)
        if num_bins < 1:
            raise ValueError(f'OccupancyCalibrationMetric: num_bins must be '
                             f'>= 1, got {num_bins}')
        self.num_bins = int(num_bins)
        self.empty_index = empty_index
        self.use_camera_mask = use_camera_mask
        self.ignore_index = ignore_index

    def process(self, data_batch, data_samples: Sequence[dict]) -> None:
        """Reduce every sample to its per-bin sums.

        Args:
            data_batch: Unused.
            data_samples (Sequence[dict]): See the class docstring.
        """
        for sample in data_samples:
            name = sample.get('sample_idx', f'#{len(self.results)}')
            if sample.get('pred_logits') is None:
                raise ValueError(
                    f'OccupancyCalibrationMetric: sample {name} has no '
                    'pred_logits (the model\'s class logits, Shape (K, X, '
                    'Y, Z))')
            logits = torch.as_tensor(sample['pred_logits']).float()
            gt = torch.as_tensor(sample['gt_occ']).to(logits.device).long()
            if tuple(logits.shape[1:]) != tuple(gt.shape):
                raise ValueError(
                    f'OccupancyCalibrationMetric: sample {name}: '
                    f'pred_logits {tuple(logits.shape)} do not match '
                    f'gt_occ {tuple(gt.shape)}')
            counted = gt != self.ignore_index
            if self.use_camera_mask:
                counted &= torch.as_tensor(sample['mask_camera']).to(
                    gt.device).bool()
            probs = logits.softmax(dim=0)
            result = dict(all=calibration_bins(probs, gt, counted,
                                               self.num_bins))
            if self.empty_index is not None:
                occupied = (gt != self.empty_index) | (
                    probs.argmax(dim=0) != self.empty_index)
                result['nonempty'] = calibration_bins(
                    probs, gt, counted & occupied, self.num_bins)
            self.results.append(result)

    def compute_metrics(self, results: list) -> Dict[str, float]:
        """ECE, mean confidence and accuracy (%), all voxels and, with
        ``empty_index``, the occupied ones (``nonempty/...``)."""
        metrics = {}
        for group in results[0] if results else ('all', ):
            bins = sum((r[group] for r in results),
                       np.zeros((3, self.num_bins)))
            scores = expected_calibration_error(bins)
            key = '' if group == 'all' else f'{group}/'
            metrics.update({f'{key}{k}': v for k, v in scores.items()})
        return metrics
