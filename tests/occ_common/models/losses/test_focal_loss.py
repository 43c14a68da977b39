"""Tests of OccFocalLoss on hand-computed voxels."""
import math

import pytest
import torch
import torch.nn.functional as F

from projects.occ_common.models.losses import OccFocalLoss

LN3 = math.log(3.0)


def _two_voxels():
    """Logits (3, 2) and labels: p = (0.75, 0.25), (0.5, 0.5), ignored."""
    logits = torch.tensor([[LN3, 0.0], [0.0, 0.0], [5.0, -5.0]],
                          requires_grad=True)
    target = torch.tensor([0, 1, 255])
    return logits, target


def test_focal_hand_computed(code_path):
    """Two supervised voxels, one ignored, gamma = 2.

    voxel 0: p_t = 3 / (3 + 1) = 0.75 -> (1 - 0.75)^2 * -ln 0.75
             = 0.0625 * 0.2876821 = 0.0179801
    voxel 1: p_t = 0.5 -> 0.25 * ln 2 = 0.25 * 0.6931472 = 0.1732868
    voxel 2: ignored.
    mean over the 2 supervised voxels = 0.1912669 / 2 = 0.0956335.
    """
    logits, target = _two_voxels()
    loss = OccFocalLoss()(logits, target)
    expected = (0.0625 * -math.log(0.75) + 0.25 * math.log(2.0)) / 2
    assert loss.item() == pytest.approx(expected, rel=1e-6)
    assert loss.item() == pytest.approx(0.0956335, abs=1e-6)
    loss.backward()
    assert torch.isfinite(logits.grad).all()
    assert torch.equal(logits.grad[2], torch.zeros(2))


def test_focal_class_weight_and_loss_weight(code_path):
    """class_weight = (2, 1), loss_weight = 0.5.

    (2 * 0.0179801 + 1 * 0.1732868) / 2 = 0.1046235; * 0.5 = 0.0523117.
    The divisor stays the number of supervised voxels (2).
    """
    logits, target = _two_voxels()
    loss = OccFocalLoss(class_weight=[2.0, 1.0], loss_weight=0.5)(logits,
                                                                  target)
    expected = 0.5 * (2 * 0.0625 * -math.log(0.75) +
                      0.25 * math.log(2.0)) / 2
    assert loss.item() == pytest.approx(expected, rel=1e-6)
    assert loss.item() == pytest.approx(0.0523117, abs=1e-6)


def test_focal_5d_matches_flat_and_keeps_inputs(code_path):
    """(B, C, X, Y, Z) = (1, 2, 3, 1, 1) holds the same three voxels.

    The loss equals the flat case (0.0956335) and neither input changes:
    the ignored label stays 255 after the call.
    """
    flat, target = _two_voxels()
    logits = flat.detach().t().reshape(1, 2, 3, 1, 1).requires_grad_()
    target_5d = target.reshape(1, 3, 1, 1)
    before_logits = logits.detach().clone()
    before_target = target_5d.clone()
    loss = OccFocalLoss()(logits, target_5d)
    assert loss.item() == pytest.approx(0.0956335, abs=1e-6)
    loss.backward()
    assert torch.equal(target_5d, before_target)
    assert torch.equal(logits.detach(), before_logits)
    assert torch.equal(logits.grad[0, :, 2], torch.zeros(2, 1, 1))


def test_focal_gamma_zero_gradient_is_cross_entropy(code_path):
    """gamma = 0 is the cross-entropy; d/dlogits = (p - onehot) / N.

    voxel 1 (p = (0.5, 0.5), label 1): grad = (0.5 - 0, 0.5 - 1) / 2
    = (0.25, -0.25). voxel 0: ((0.75 - 1), 0.25) / 2 = (-0.125, 0.125).
    """
    logits, target = _two_voxels()
    loss = OccFocalLoss(gamma=0.0)(logits, target)
    reference = F.cross_entropy(
        logits.detach(), target, ignore_index=255).item()
    assert loss.item() == pytest.approx(reference, rel=1e-6)
    loss.backward()
    expected = torch.tensor([[-0.125, 0.125], [0.25, -0.25], [0.0, 0.0]])
    assert torch.allclose(logits.grad, expected, atol=1e-6)


def test_focal_all_ignored_is_finite_zero(code_path):
    """Every voxel ignored: the loss is 0 and every gradient 0."""
    logits = torch.randn(2, 3, 2, 2, 1, requires_grad=True)
    target = torch.full((2, 2, 2, 1), 255)
    loss = OccFocalLoss()(logits, target)
    assert loss.item() == 0.0
    loss.backward()
    assert torch.equal(logits.grad, torch.zeros_like(logits))


def test_focal_bad_inputs_raise():
    """Out-of-range labels, shape mismatch and weight count are errors."""
    logits = torch.zeros(1, 2, 2, 1, 1)
    with pytest.raises(ValueError, match=r'labels in \[0, 2\)'):
        OccFocalLoss()(logits, torch.tensor([[[[0]], [[5]]]]))
    with pytest.raises(ValueError, match='expected target of shape'):
        OccFocalLoss()(logits, torch.zeros(1, 3, 1, 1, dtype=torch.long))
    with pytest.raises(ValueError, match='2 class weights'):
        OccFocalLoss(class_weight=[1.0])(
            logits, torch.zeros(1, 2, 1, 1).long())
    with pytest.raises(ValueError, match='integer target'):
        OccFocalLoss()(logits, torch.zeros(1, 2, 1, 1))
    with pytest.raises(ValueError, match='gamma'):
        OccFocalLoss(gamma=-1.0)
