"""Tests of the Cartesian <-> cylindrical conversion."""
import math

import pytest
import torch

from projects.occ_common.models.layers import (cartesian_to_cylindrical,
                                               cylindrical_to_cartesian)


def test_hand_computed_values():
    """(1, 1, 2) -> r = sqrt(2), theta = pi / 4; (0, -3, -1) -> r = 3,
    theta = -pi / 2; (-2, 0, 0) -> r = 2, theta = pi; the origin -> 0, 0."""
    xyz = torch.tensor([[1.0, 1.0, 2.0], [0.0, -3.0, -1.0], [-2.0, 0.0, 0.0],
                        [0.0, 0.0, 5.0]],
                       dtype=torch.float64)
    expected = torch.tensor(
        [[math.sqrt(2), math.pi / 4, 2.0], [3.0, -math.pi / 2, -1.0],
         [2.0, math.pi, 0.0], [0.0, 0.0, 5.0]],
        dtype=torch.float64)
    torch.testing.assert_close(cartesian_to_cylindrical(xyz), expected)
    back = cylindrical_to_cartesian(expected)
    torch.testing.assert_close(back, xyz, atol=1e-12, rtol=0)


def test_round_trip_random_points():
    """cyl -> cart -> cyl and cart -> cyl -> cart are identities."""
    gen = torch.Generator().manual_seed(0)
    xyz = torch.randn(50, 3, generator=gen, dtype=torch.float64) * 30
    cyl = cartesian_to_cylindrical(xyz)
    torch.testing.assert_close(cylindrical_to_cartesian(cyl), xyz)
    assert bool((cyl[:, 1].abs() <= math.pi).all())
    torch.testing.assert_close(
        cartesian_to_cylindrical(cylindrical_to_cartesian(cyl)), cyl)


def test_gradient_and_empty():
    """d r / d x = x / r = 3 / 5 at (3, 4); an empty batch stays empty."""
    xyz = torch.tensor([[3.0, 4.0, 1.0]], requires_grad=True)
    cartesian_to_cylindrical(xyz)[:, 0].sum().backward()
    torch.testing.assert_close(xyz.grad, torch.tensor([[0.6, 0.8, 0.0]]))
    empty = torch.zeros(0, 3, requires_grad=True)
    out = cartesian_to_cylindrical(empty)
    assert out.shape == (0, 3)
    out.sum().backward()
    assert empty.grad.shape == (0, 3)


def test_bad_shape_raises():
    """A last dimension other than 3 is refused with the shape named."""
    with pytest.raises(ValueError, match=r'\(4, 2\)'):
        cartesian_to_cylindrical(torch.zeros(4, 2))
    with pytest.raises(ValueError, match='cylindrical_to_cartesian'):
        cylindrical_to_cartesian(torch.zeros(4))
