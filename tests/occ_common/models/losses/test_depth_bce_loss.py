"""Tests of the BEVDepth depth loss and its bin targets."""
import math

import pytest
import torch

from projects.occ_common.models.losses import DepthBCELoss
from projects.occ_common.synthetic.occ_inputs import (PATCH_DEPTH_BOUND,
                                                      patch_depth_map)

BOUND = PATCH_DEPTH_BOUND  # 4 bins of 1 m from 1 m


def test_depth_loss_hand_computed(code_path):
    """Two pixels with a target, BCE summed over bins, mean over pixels.

    pixel (0, 0): target bin 1, pred (0.25, 0.25, 0.25, 0.25)
      3 * -ln(0.75) + -ln(0.25) = 3 ln(4/3) + 2 ln 2
    pixel (1, 1): target bin 0, pred (0.5, 0.5, 0, 0)
      -ln 0.5 - ln 0.5 - ln 1 - ln 1 = 2 ln 2
    mean = (3 ln(4/3) + 4 ln 2) / 2 = 1.8178174; * loss_weight 3
    = 5.4534523. The two pixels without target add nothing.
    """
    pred = torch.zeros(1, 4, 2, 2)
    pred[0, :, 0, 0] = 0.25
    pred[0, :, 1, 1] = torch.tensor([0.5, 0.5, 0.0, 0.0])
    pred[0, :, 0, 1] = torch.tensor([1.0, 0.0, 0.0, 0.0])  # no target
    pred.requires_grad_()
    loss = DepthBCELoss(
        depth_bound=BOUND, downsample=2)(pred, patch_depth_map())
    expected = 3 * (3 * math.log(4 / 3) + 4 * math.log(2)) / 2
    assert loss.item() == pytest.approx(expected, rel=1e-6)
    assert loss.item() == pytest.approx(5.4534523, abs=1e-6)
    loss.backward()
    assert torch.isfinite(pred.grad).all()
    assert torch.equal(pred.grad[0, :, 0, 1], torch.zeros(4))


def test_nearest_bin_changes_the_target_the_loss_pulls_to(code_path):
    """One pixel at 2.6 m, bins lifted at 1, 2, 3, 4 m, prediction (0.1,
    0.1, 0.7, 0.1). floor: bin 1 (2 m), BCE -2 ln 0.9 - ln 0.1 - ln 0.3 =
    0.2107210 + 2.3025851 + 1.2039728 = 3.7172789; nearest_bin: bin 2 (3
    m, 0.4 m away, not 0.6), BCE -3 ln 0.9 - ln 0.7 = 0.3160815 + 0.3566749
    = 0.6727564. A descent step raises bin 1 under floor, bin 2 under
    nearest_bin (the target's gradient is negative, the others' positive)."""
    depth = torch.tensor([[[2.6]]])
    losses, grads = {}, {}
    for nearest in (False, True):
        pred = torch.tensor([0.1, 0.1, 0.7, 0.1]).view(1, 4, 1, 1)
        pred.requires_grad_()
        loss = DepthBCELoss(BOUND, downsample=1, loss_weight=1.0,
                            nearest_bin=nearest)(pred, depth)
        loss.backward()
        losses[nearest], grads[nearest] = loss.item(), pred.grad.flatten()
    assert losses[False] == pytest.approx(
        -2 * math.log(0.9) - math.log(0.1) - math.log(0.3), rel=1e-6)
    assert losses[False] == pytest.approx(3.7172789, abs=1e-6)
    assert losses[True] == pytest.approx(0.6727564, abs=1e-6)
    assert grads[False][1] < 0 < grads[False][2]
    assert grads[True][2] < 0 < grads[True][1]


@pytest.mark.parametrize('bad', [float('nan'), float('inf')])
def test_non_finite_prediction_gives_nan_not_a_crash(bad, code_path):
    """A diverged depth net: BCE raised "all elements of input should be
    between 0 and 1"; now the loss is NaN (for NonFiniteLossHook to name)
    and backward stays finite. A bad value at a pixel without a target
    changes nothing."""
    pred = torch.full((1, 4, 2, 2), 0.25)
    loss_fn = DepthBCELoss(depth_bound=BOUND, downsample=2)
    good = loss_fn(pred, patch_depth_map())
    untargeted = pred.clone()
    untargeted[0, :, 0, 1] = bad  # feature pixel (0, 1) has no return
    assert loss_fn(untargeted, patch_depth_map()).item() == good.item()
    pred[0, 2, 1, 1] = bad  # feature pixel (1, 1) has one
    pred.requires_grad_()
    loss = loss_fn(pred, patch_depth_map())
    assert torch.isnan(loss)
    loss.backward()
    assert torch.isfinite(pred.grad).all()


def test_no_lidar_is_finite_zero(code_path):
    """No LiDAR return anywhere: 0 with zero gradients."""
    pred = torch.full((2, 4, 2, 2), 0.25, requires_grad=True)
    loss = DepthBCELoss(
        depth_bound=BOUND, downsample=2)(pred, torch.zeros(2, 4, 4))
    assert loss.item() == 0.0
    loss.backward()
    assert torch.equal(pred.grad, torch.zeros_like(pred))


def test_default_bins_and_bad_inputs():
    """(1, 50, 1) gives D = 49; wrong D, size or stride raise."""
    assert DepthBCELoss().num_bins == 49
    loss = DepthBCELoss(depth_bound=BOUND, downsample=2)
    with pytest.raises(ValueError, match='4, h, w'):
        loss(torch.zeros(1, 3, 2, 2), patch_depth_map())
    with pytest.raises(ValueError, match='does not match'):
        loss(torch.zeros(1, 4, 1, 2), patch_depth_map())
    with pytest.raises(ValueError, match='dmin < dmax'):
        DepthBCELoss(depth_bound=(5.0, 1.0, 1.0))


def _hand_case():
    """The two-pixel prediction of test_depth_loss_hand_computed."""
    pred = torch.zeros(1, 4, 2, 2)
    pred[0, :, 0, 0] = 0.25
    pred[0, :, 1, 1] = torch.tensor([0.5, 0.5, 0.0, 0.0])
    return pred


def test_depth_loss_under_autocast(monkeypatch):
    """``--amp`` wraps the loss in autocast, where CUDA refuses
    ``binary_cross_entropy`` ("unsafe to autocast"). Emulating that refusal
    on CPU, the loss still runs (autocast is off around the BCE) and gives
    the float32 value of test_depth_loss_hand_computed, 5.4534523."""
    from projects.occ_common.models.losses import depth_bce_loss
    real_bce = depth_bce_loss.F.binary_cross_entropy

    def refusing_bce(*args, **kwargs):
        if torch.is_autocast_enabled('cpu'):
            raise RuntimeError('binary_cross_entropy is unsafe to autocast')
        return real_bce(*args, **kwargs)

    monkeypatch.setattr(depth_bce_loss.F, 'binary_cross_entropy', refusing_bce)
    pred = _hand_case().requires_grad_()
    with torch.autocast('cpu', dtype=torch.bfloat16):
        loss = DepthBCELoss(
            depth_bound=BOUND, downsample=2)(pred, patch_depth_map())
    assert loss.dtype == torch.float32
    assert loss.item() == pytest.approx(5.4534523, abs=1e-6)
    loss.backward()
    assert torch.isfinite(pred.grad).all()


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs CUDA')
def test_depth_loss_under_cuda_autocast():
    """Real CUDA float16 autocast: no 'unsafe to autocast' error, and the
    float32 value 5.4534523 of test_depth_loss_hand_computed."""
    pred = _hand_case().cuda().half().requires_grad_()
    with torch.autocast('cuda', dtype=torch.float16):
        loss = DepthBCELoss(
            depth_bound=BOUND,
            downsample=2)(pred, patch_depth_map().cuda())
    assert loss.item() == pytest.approx(5.4534523, abs=1e-5)
    loss.backward()
    assert torch.isfinite(pred.grad).all()
