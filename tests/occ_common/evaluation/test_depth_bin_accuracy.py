"""DepthBinAccuracy against hand-computed values."""
import math

import pytest
import torch

from projects.occ_common.evaluation import DepthBinAccuracy

#: Bins at 1, 2, 3, 4 m (D = 4).
BOUND = (1.0, 5.0, 1.0)


def _maps():
    """Two images of 2x4 pixels at stride 2 (1x2 feature pixels each).

    Image 0: the left patch's nearest return is 2.2 m (of 2.2 and 2.9;
    nearest bin point 2 m, bin 1), the right patch has none. Image 1: the
    left patch's nearest return is 3.0 m (of 3.9 and 3.0; bin 2), the right
    patch's 7.0 m lies beyond the bins and does not count.
    """
    gt = torch.zeros(2, 2, 4)
    gt[0, 0, 0], gt[0, 1, 1] = 2.2, 2.9
    gt[1, 0, 0], gt[1, 1, 0] = 3.9, 3.0
    gt[1, 0, 3] = 7.0
    depth = torch.full((2, 4, 1, 2), 0.25)
    depth[0, :, 0, 0] = torch.tensor([0.1, 0.6, 0.2, 0.1])
    depth[1, :, 0, 0] = torch.tensor([0.0, 1.0, 0.0, 0.0])
    return depth, gt


def test_hand_computed_statistics():
    """Two pixels count (image 0 left at 2.2 m, image 1 left at 3.0 m).

    Pixel A, p = (0.1, 0.6, 0.2, 0.1), bin 1: right (top1 and within one);
    p_true 0.6; expected error 0.1*1.2 + 0.6*0.2 + 0.2*0.8 + 0.1*1.8 =
    0.58 m; entropy -(2*0.1 ln 0.1 + 0.6 ln 0.6 + 0.2 ln 0.2) = 1.088900.
    Pixel B, one-hot on bin 1, true bin 2: wrong, within one; p_true 0;
    error |2 - 3.0| = 1.0 m; entropy 0.
    Means: top1 50 %, within one 100 %, p_true 0.3, error 0.79 m, entropy
    0.544450 nats; uniform ln 4.
    """
    acc = DepthBinAccuracy(BOUND)
    depth, gt = _maps()
    acc.update(depth, gt)
    out = acc.summary()
    entropy_a = -(2 * 0.1 * math.log(0.1) + 0.6 * math.log(0.6) +
                  0.2 * math.log(0.2))
    assert out['cells'] == 2
    assert out['top1'] == pytest.approx(50.0)
    assert out['within_one_bin'] == pytest.approx(100.0)
    assert out['prob_true'] == pytest.approx(0.3, abs=1e-7)
    assert out['expected_error_m'] == pytest.approx(0.79, abs=1e-6)
    assert out['entropy'] == pytest.approx(entropy_a / 2, abs=1e-6)
    assert out['uniform_entropy'] == pytest.approx(math.log(4))


def test_batches_accumulate_like_one():
    """The two images added one at a time give the same summary."""
    depth, gt = _maps()
    whole, split = DepthBinAccuracy(BOUND), DepthBinAccuracy(BOUND)
    whole.update(depth, gt)
    split.update(depth[:1], gt[:1])
    split.update(depth[1:], gt[1:])
    assert split.summary() == pytest.approx(whole.summary())


def test_bad_inputs_raise():
    depth, gt = _maps()
    acc = DepthBinAccuracy(BOUND)
    with pytest.raises(ValueError, match=r'\(M, 4, h, w\)'):
        acc.update(depth[:, :3], gt)
    with pytest.raises(ValueError, match='integer stride'):
        acc.update(depth, gt[:, :, :3])
    with pytest.raises(ValueError, match='integer stride'):
        acc.update(depth, gt[0])
    with pytest.raises(ValueError, match='no feature pixel'):
        acc.summary()
