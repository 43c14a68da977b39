"""Tests of the spatial group pooling (eqs. 8-13)."""
import pytest
import torch

from projects.occ_cyl import SpatialGroupPooling


def _volume():
    """(B=1, C=2, R=2, Theta=4, Z=4): channel 0 holds
    v = 100 r + 10 t + z and channel 1 holds -v."""
    r, t, z = torch.meshgrid(
        torch.arange(2.), torch.arange(4.), torch.arange(4.), indexing='ij')
    v = 100 * r + 10 * t + z
    return torch.stack([v, -v])[None]


def test_group_pool_hand_computed_planes():
    """M = 2, channel g * C + c = channel c of group g.

    Along Z (groups z in {0, 1}, {2, 3}): channel 0 of group g is
    100 r + 10 t + (2 g + 1), channel 1 is -(100 r + 10 t + 2 g).
    Along R (groups {0}, {1}): group g is 100 g + 10 t + z and its negation.
    Along Theta (groups t in {0, 1}, {2, 3}): 100 r + 10 (2 g + 1) + z and
    -(100 r + 10 (2 g) + z).
    """
    pool = SpatialGroupPooling(2, 3, num_groups=2)
    vol = _volume()
    r, t = torch.meshgrid(torch.arange(2.), torch.arange(4.), indexing='ij')
    z_planes = pool.group_pool(vol, 4)
    assert z_planes.shape == (1, 4, 2, 4)
    for g in range(2):
        torch.testing.assert_close(z_planes[0, 2 * g],
                                   100 * r + 10 * t + 2 * g + 1)
        torch.testing.assert_close(z_planes[0, 2 * g + 1],
                                   -(100 * r + 10 * t + 2 * g))
    t2, z2 = torch.meshgrid(torch.arange(4.), torch.arange(4.), indexing='ij')
    r_planes = pool.group_pool(vol, 2)
    assert r_planes.shape == (1, 4, 4, 4)
    for g in range(2):
        torch.testing.assert_close(r_planes[0, 2 * g], 100 * g + 10 * t2 + z2)
        torch.testing.assert_close(r_planes[0, 2 * g + 1],
                                   -(100 * g + 10 * t2 + z2))
    r3, z3 = torch.meshgrid(torch.arange(2.), torch.arange(4.), indexing='ij')
    t_planes = pool.group_pool(vol, 3)
    assert t_planes.shape == (1, 4, 2, 4)
    for g in range(2):
        torch.testing.assert_close(t_planes[0, 2 * g],
                                   100 * r3 + 10 * (2 * g + 1) + z3)
        torch.testing.assert_close(t_planes[0, 2 * g + 1],
                                   -(100 * r3 + 20 * g + z3))


def test_one_group_is_plain_max_pooling():
    """M = 1 (Table VII): along Z the plane is max_z v = 100 r + 10 t + 3."""
    pool = SpatialGroupPooling(2, 3, num_groups=1)
    r, t = torch.meshgrid(torch.arange(2.), torch.arange(4.), indexing='ij')
    plane = pool.group_pool(_volume(), 4)
    torch.testing.assert_close(plane[0, 0], 100 * r + 10 * t + 3)
    torch.testing.assert_close(plane[0, 1], -(100 * r + 10 * t))


def test_forward_shapes_and_backward():
    """The MLP maps M * C channels to out_channels for the (R, Theta),
    (Theta, Z), (R, Z) planes; the gradient reaches each group's maximum
    only: summing channel 0 of both Z groups puts 1 on z = 1 and z = 3 of
    each of the 2 x 4 (r, t) cells, i.e. 8 per z slice, 0 on z = 0, 2."""
    pool = SpatialGroupPooling(2, 3, num_groups=2)
    vol = _volume().requires_grad_()
    planes = pool(vol)
    assert [tuple(p.shape) for p in planes] == [(1, 3, 2, 4), (1, 3, 4, 4),
                                                (1, 3, 2, 4)]
    sum(p.sum() for p in planes).backward()
    assert pool.mlps[1][0].conv.weight.grad is not None
    vol2 = _volume().requires_grad_()
    pool.group_pool(vol2, 4)[:, 0::2].sum().backward()
    grad_z = vol2.grad[0, 0].sum(dim=(0, 1))
    assert grad_z.tolist() == [0.0, 8.0, 0.0, 8.0]


def test_empty_batch():
    """A batch of zero volumes gives zero-sized planes."""
    pool = SpatialGroupPooling(2, 3, num_groups=2).eval()
    planes = pool(torch.zeros(0, 2, 2, 4, 4))
    assert planes[0].shape == (0, 3, 2, 4)


def test_bad_inputs_raise():
    """Indivisible axes, wrong channels and a bad axis are named."""
    pool = SpatialGroupPooling(2, 3, num_groups=3)
    with pytest.raises(ValueError, match='not divisible into 3 groups'):
        pool.group_pool(_volume(), 4)
    with pytest.raises(ValueError, match=r'\(B, 2, R, Theta, Z\)'):
        pool.group_pool(torch.zeros(1, 3, 3, 3, 3), 4)
    with pytest.raises(ValueError, match='axis'):
        pool.group_pool(torch.zeros(1, 2, 3, 3, 3), 1)
    with pytest.raises(ValueError, match='num_groups'):
        SpatialGroupPooling(2, 3, num_groups=0)
