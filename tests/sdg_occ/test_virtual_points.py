"""Tests of the bidirectional linear incremental discretization."""
import pytest
import torch

from projects.sdg_occ import (bilinear_incremental_discretization,
                              interpolate_depth_prob, virtual_point_depths)

# Bins (1, 5, 1): D = 4 bins at depths 1, 2, 3, 4.
BOUND = (1.0, 5.0, 1.0)


def _prob(scale=1.0):
    """Two pixels (1x2 map) with distributions p and q over the 4 bins,
    times ``scale`` (a distribution need not sum to 1)."""
    prob = torch.tensor([[0.1, 0.2, 0.3, 0.4], [0.4, 0.3, 0.2, 0.1]])
    return (scale * prob).t().reshape(1, 4, 1, 2).contiguous()


def test_virtual_depths_step_out_from_d_both_ways():
    """d = 2.5: r = 1, l = 2 -> steps of 0.5: 1.5, 2, 2.5, 3, 3.5; the
    paper's r = 1, l = 8 -> 17 depths 0.125 apart from 1.5 to 3.5; r = 2,
    l = 4 (Table 4's coarsest) -> 9 depths 0.5 apart from 0.5 to 4.5;
    r = 0 -> 2 l + 1 copies of d."""
    ext = torch.full((1, 1, 1), 2.5)
    assert torch.allclose(
        virtual_point_depths(ext, 1.0, 2).flatten(),
        torch.tensor([1.5, 2.0, 2.5, 3.0, 3.5]))
    paper = virtual_point_depths(ext, 1.0, 8).flatten()
    assert paper.shape == (17, )
    assert torch.allclose(paper, 1.5 + 0.125 * torch.arange(17))
    coarse = virtual_point_depths(ext, 2.0, 4).flatten()
    assert torch.allclose(coarse, 0.5 + 0.5 * torch.arange(9))
    assert torch.equal(
        virtual_point_depths(ext, 0.0, 1).flatten(), torch.full((3, ), 2.5))


def test_interpolated_values_by_hand():
    """p = (0.1, 0.2, 0.3, 0.4) at bin depths 1, 2, 3, 4.

    depth 1.5 -> 0.5*0.1 + 0.5*0.2 = 0.15; 2.5 -> 0.25; 3.5 -> 0.35;
    exactly on a bin (1.0, 4.0) -> that bin's 0.1, 0.4; 2.25 -> 0.75*0.2 +
    0.25*0.3 = 0.225; 0.5 before the first bin -> p[0] = 0.1; 4.5 and 9
    past the last -> p[3] = 0.4.
    """
    prob = _prob()[..., :1]
    depths = torch.tensor([1.5, 2.5, 3.5, 1.0, 4.0, 2.25, 0.5, 4.5,
                           9.0]).view(1, 9, 1, 1)
    values = interpolate_depth_prob(prob, depths, BOUND)
    assert torch.allclose(
        values.flatten(),
        torch.tensor([0.15, 0.25, 0.35, 0.1, 0.4, 0.225, 0.1, 0.4, 0.4]))


def test_interpolation_runs_on_the_sid_coordinate():
    """SID bins (1, 5, 1, 'sid') lie at 1, 1.587, 2.520, 4 m; 2 m is at
    coordinate 3 log 2 / log 4 = 1.5, halfway between bins 1 and 2: p gives
    (0.2 + 0.3) / 2 = 0.25 and q 0.25; 4 m is bin 3 exactly (0.4, 0.1),
    where the uniform bins would put it too (4 m is their bin 3 as well),
    while 2 m is uniform bin 1 (0.2, 0.3)."""
    depths = torch.tensor([2.0, 4.0]).view(1, 2, 1, 1).expand(1, 2, 1, 2)
    sid = interpolate_depth_prob(_prob(), depths, BOUND + ('sid', ))
    torch.testing.assert_close(
        sid[0, :, 0], torch.tensor([[0.25, 0.25], [0.4, 0.1]]))
    uniform = interpolate_depth_prob(_prob(), depths, BOUND)
    torch.testing.assert_close(
        uniform[0, :, 0], torch.tensor([[0.2, 0.3], [0.4, 0.1]]))


def test_weight_mass_equals_distribution_mass_per_pixel():
    """Item 5 of issue 12: a pixel's virtual points carry its whole depth
    mass, whatever r and l, also where d lies beyond the last bin.

    Distributions scaled by 0.7 (mass 0.7 per pixel), r = 1, l = 1 (3
    points). Pixel 0, d = 2.5: values 0.7 * (0.15, 0.25, 0.35), total
    0.7 * 0.75 -> weights 0.7 * (0.2, 1/3, 7/15), sum 0.7. Pixel 1, d = 6
    (all of 5, 6, 7 past the last bin 4): each reads q[3] = 0.07 -> 0.7 / 3
    each, lifted at 5, 6, 7 m (the old code dropped the pixel). With
    r = 2, l = 4 and r = 1, l = 8 the sums are 0.7 too (they were 0.0-0.65
    and 1.7-1.85 times the mass before the rescaling)."""
    prob = _prob(0.7)
    ext = torch.tensor([[[2.5, 6.0]]])
    depths, weights, valid = bilinear_incremental_discretization(
        ext, prob, BOUND, radius=1.0, num_layers=1)
    assert valid.all()
    assert torch.allclose(weights[0, :, 0, 0],
                          0.7 * torch.tensor([0.2, 1 / 3, 7 / 15]))
    assert torch.allclose(weights[0, :, 0, 1], torch.full((3, ), 0.7 / 3))
    assert depths[0, :, 0, 1].tolist() == [5.0, 6.0, 7.0]
    for radius, layers in ((2.0, 4), (1.0, 8), (1.0, 12)):
        for d in (1.3, 2.5, 4.4, 30.0):
            ext = torch.full((1, 1, 2), d)
            _, weights, _ = bilinear_incremental_discretization(
                ext, prob, BOUND, radius, layers)
            assert torch.allclose(weights.sum(1), torch.full((1, 1, 2), 0.7))


def test_points_behind_the_camera_are_invalid():
    """d = 0.5, r = 1, l = 2: depths -0.5 and 0 are not in front of the
    camera; 0.5, 1.0 and 1.5 read p[0] = 0.1 (clamped), 0.1 and 0.15 ->
    weights 2/7, 2/7, 3/7 of the mass 1."""
    ext = torch.tensor([[[0.5, 0.0]]])
    _, weights, valid = bilinear_incremental_discretization(
        ext, _prob(), BOUND, radius=1.0, num_layers=2)
    assert valid[0, :, 0, 0].tolist() == [False, False, True, True, True]
    assert torch.allclose(weights[0, :, 0, 0],
                          torch.tensor([0, 0, 2 / 7, 2 / 7, 3 / 7]))


def test_pixels_without_depth_and_backward():
    """Pixel 1 has no extended depth: no valid point, weight 0, no
    gradient. Pixel 0: the weights sum to sum_k p_k, so d(sum of
    weights)/dp = 1 for each of its bins."""
    prob = _prob().requires_grad_(True)
    ext = torch.tensor([[[2.5, 0.0]]])
    _, weights, valid = bilinear_incremental_discretization(
        ext, prob, BOUND, radius=1.0, num_layers=1)
    assert not valid[0, :, 0, 1].any()
    assert torch.equal(weights[0, :, 0, 1], torch.zeros(3))
    weights.sum().backward()
    assert torch.allclose(prob.grad[0, :, 0, 0], torch.ones(4))
    assert torch.equal(prob.grad[0, :, 0, 1], torch.zeros(4))


def test_empty_batch():
    """No camera at all: shapes (0, 2 l + 1, h, w), nothing valid."""
    prob = torch.zeros(0, 4, 2, 3, requires_grad=True)
    depths, weights, valid = bilinear_incremental_discretization(
        torch.zeros(0, 2, 3), prob, BOUND, 1.0, 8)
    assert depths.shape == (0, 17, 2, 3) and not valid.any()
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
    with pytest.raises(ValueError, match='radius'):
        virtual_point_depths(torch.zeros(1, 1, 1), -1.0, 2)
