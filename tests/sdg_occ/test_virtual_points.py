"""Tests of the bilinear incremental discretization (virtual points)."""
import pytest
import torch

from projects.sdg_occ import (bilinear_incremental_discretization,
                              interpolate_depth_prob, virtual_point_depths)

# Bins (1, 5, 1): D = 4 bins at depths 1, 2, 3, 4.
BOUND = (1.0, 5.0, 1.0)


def _prob():
    """Two pixels (1x2 map) with distributions p and q over the 4 bins."""
    prob = torch.tensor([[0.1, 0.2, 0.3, 0.4], [0.4, 0.3, 0.2, 0.1]])
    return prob.t().reshape(1, 4, 1, 2).contiguous()


def test_virtual_depths_evenly_spaced():
    """d = 2.5, r = 1: L = 3 -> 1.5, 2.5, 3.5; L = 5 -> steps of 0.5;
    the paper's r = 1, L = 8 -> 2.5 - 1 + 2 l / 7; L = 1 -> d itself."""
    ext = torch.full((1, 1, 1), 2.5)
    assert torch.allclose(
        virtual_point_depths(ext, 1.0, 3).flatten(),
        torch.tensor([1.5, 2.5, 3.5]))
    assert torch.allclose(
        virtual_point_depths(ext, 1.0, 5).flatten(),
        torch.tensor([1.5, 2.0, 2.5, 3.0, 3.5]))
    paper = 1.5 + 2.0 * torch.arange(8) / 7
    assert torch.allclose(virtual_point_depths(ext, 1.0, 8).flatten(), paper)
    assert torch.equal(
        virtual_point_depths(ext, 1.0, 1).flatten(), torch.tensor([2.5]))


def test_interpolated_weights_by_hand():
    """p = (0.1, 0.2, 0.3, 0.4) at bin depths 1, 2, 3, 4.

    depth 1.5 -> 0.5*0.1 + 0.5*0.2 = 0.15; 2.5 -> 0.25; 3.5 -> 0.35;
    exactly on a bin (1.0, 4.0) -> that bin's 0.1, 0.4; 2.25 -> 0.75*0.2 +
    0.25*0.3 = 0.225; 0.5 and 4.5 are outside [1, 4] -> weight 0, invalid.
    """
    prob = _prob()[..., :1]
    depths = torch.tensor([1.5, 2.5, 3.5, 1.0, 4.0, 2.25, 0.5,
                           4.5]).view(1, 8, 1, 1)
    weights, valid = interpolate_depth_prob(prob, depths, BOUND)
    assert torch.allclose(
        weights.flatten(),
        torch.tensor([0.15, 0.25, 0.35, 0.1, 0.4, 0.225, 0.0, 0.0]))
    assert valid.flatten().tolist() == [True] * 6 + [False] * 2


def test_discretization_masks_pixels_without_depth_and_backward():
    """Pixel 0 has d = 2.5 (r = 1, L = 3), pixel 1 none.

    Pixel 0 weights 0.15, 0.25, 0.35 as above; pixel 1 all invalid, 0.
    d(sum of weights)/dp for pixel 0: depth 1.5 splits 0.5 / 0.5 between
    bins 0 and 1, 2.5 between bins 1 and 2, 3.5 between bins 2 and 3 ->
    (0.5, 1, 1, 0.5); pixel 1 gets 0.
    """
    prob = _prob().requires_grad_(True)
    ext = torch.tensor([[[2.5, 0.0]]])
    depths, weights, valid = bilinear_incremental_discretization(
        ext, prob, BOUND, radius=1.0, num_layers=3)
    assert depths.shape == weights.shape == valid.shape == (1, 3, 1, 2)
    assert torch.allclose(weights[0, :, 0, 0],
                          torch.tensor([0.15, 0.25, 0.35]))
    assert torch.equal(weights[0, :, 0, 1], torch.zeros(3))
    assert valid[0, :, 0, 0].all() and not valid[0, :, 0, 1].any()
    weights.sum().backward()
    assert torch.allclose(prob.grad[0, :, 0, 0],
                          torch.tensor([0.5, 1.0, 1.0, 0.5]))
    assert torch.equal(prob.grad[0, :, 0, 1], torch.zeros(4))


def test_near_range_end_drops_outside_points():
    """d = 4.5, r = 1, L = 3 -> 3.5 (weight 0.5*0.3 + 0.5*0.4 = 0.35),
    4.5 and 5.5 beyond the last bin (4) -> invalid."""
    ext = torch.tensor([[[4.5, 0.0]]])
    _, weights, valid = bilinear_incremental_discretization(
        ext, _prob(), BOUND, radius=1.0, num_layers=3)
    assert torch.allclose(weights[0, :, 0, 0], torch.tensor([0.35, 0., 0.]))
    assert valid[0, :, 0, 0].tolist() == [True, False, False]


def test_empty_batch():
    """No camera at all: shapes (0, L, h, w), nothing valid."""
    prob = torch.zeros(0, 4, 2, 3, requires_grad=True)
    depths, weights, valid = bilinear_incremental_discretization(
        torch.zeros(0, 2, 3), prob, BOUND, 1.0, 8)
    assert depths.shape == (0, 8, 2, 3) and not valid.any()
    weights.sum().backward()
    assert prob.grad.shape == (0, 4, 2, 3)


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match='depth_prob must have shape'):
        interpolate_depth_prob(
            torch.zeros(1, 3, 1, 1), torch.zeros(1, 2, 1, 1), BOUND)
    with pytest.raises(ValueError, match='depths must have shape'):
        interpolate_depth_prob(
            torch.zeros(1, 4, 1, 1), torch.zeros(1, 2, 2, 1), BOUND)
    with pytest.raises(ValueError, match='num_layers'):
        virtual_point_depths(torch.zeros(1, 1, 1), 1.0, 0)
