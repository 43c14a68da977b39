"""Expected calibration error of voxel probabilities, by hand."""
import math

import numpy as np
import pytest
import torch

from projects.occ_common.evaluation import OccupancyCalibrationMetric


def _sample(mask=None):
    """Six voxels of two classes (K=2, grid 6 x 1 x 1): probabilities
    (0.9, 0.1) GT 0, (0.6, 0.4) GT 1, (0.3, 0.7) GT 1, (0.5, 0.5) GT 1
    (the tie goes to class 0), then one ignored voxel (GT 255) and one
    that a camera mask hides."""
    probs = torch.tensor([[0.9, 0.1], [0.6, 0.4], [0.3, 0.7], [0.5, 0.5],
                          [0.99, 0.01], [0.2, 0.8]])
    sample = dict(pred_logits=probs.log().T.reshape(2, 6, 1, 1),
                  gt_occ=torch.tensor([0, 1, 1, 1, 255, 0]).reshape(6, 1, 1),
                  sample_idx=0)
    if mask is not None:
        sample['mask_camera'] = torch.tensor(mask).reshape(6, 1, 1)
    return sample


def _metrics(sample, **kwargs):
    metric = OccupancyCalibrationMetric(num_bins=10, **kwargs)
    metric.process(None, [sample])
    return metric.compute_metrics(metric.results)


def test_ece_by_hand():
    """With the mask hiding voxel 6: each counted voxel alone in its bin
    (0.9 -> 9, 0.6 -> 6, 0.7 -> 7, 0.5 -> 5); |accuracy - confidence| =
    0.1, 0.6, 0.3, 0.5: ECE = 1.5 / 4 = 37.5 %, mean confidence 67.5 %,
    accuracy 50 %. Over the voxels occupied in GT or prediction (not the
    first: empty and predicted empty): (0.6 + 0.3 + 0.5) / 3 = 46.67 %."""
    sample = _sample(mask=[True] * 5 + [False])
    out = _metrics(sample, empty_index=0, use_camera_mask=True)
    assert out['ECE'] == pytest.approx(37.5)
    assert out['confidence'] == pytest.approx(67.5)
    assert out['accuracy'] == pytest.approx(50.0)
    assert out['nonempty/ECE'] == pytest.approx(140 / 3)


def test_without_the_mask_the_sixth_voxel_counts():
    """Voxel 6 (0.8 for class 1, GT 0: wrong, bin 8) adds |0 - 0.8|:
    ECE = (1.5 + 0.8) / 5 = 46 %."""
    assert _metrics(_sample())['ECE'] == pytest.approx(46.0)


def test_no_counted_voxel_is_nan():
    sample = _sample(mask=[False] * 6)
    assert math.isnan(_metrics(sample, use_camera_mask=True)['ECE'])


def test_missing_logits_are_named():
    sample = _sample()
    del sample['pred_logits']
    with pytest.raises(ValueError, match='no pred_logits'):
        OccupancyCalibrationMetric().process(None, [sample])


def test_bins_sum_over_samples():
    """Two copies of the sample give the same ECE as one."""
    metric = OccupancyCalibrationMetric(num_bins=10)
    metric.process(None, [_sample(), _sample()])
    out = metric.compute_metrics(metric.results)
    assert out['ECE'] == pytest.approx(46.0)
    assert np.isfinite(out['confidence'])
