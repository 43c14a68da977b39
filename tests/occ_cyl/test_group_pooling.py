"""Tests of the spatial group pooling (eqs. 8-13)."""
import pytest
import torch

from projects.occ_common.testing.autograd_memory import recorded_training_step
from projects.occ_cyl import SpatialGroupPooling
from projects.occ_cyl.group_pooling import PLANE_POOL_AXES

SHAPE = (2, 4, 4)  # (R, Theta, Z)


def _volume():
    """(B=1, C=2, R=2, Theta=4, Z=4): channel 0 holds
    v = 100 r + 10 t + z and channel 1 holds -v."""
    r, t, z = torch.meshgrid(
        torch.arange(2.), torch.arange(4.), torch.arange(4.), indexing='ij')
    v = 100 * r + 10 * t + z
    return torch.stack([v, -v])[None]


def _rows(volume, mask=None):
    """The occupied voxels of a dense volume as (features (U, C),
    coordinates (U, 4)); ``mask`` (B, R, Theta, Z) marks the occupied
    ones (all by default)."""
    if mask is None:
        mask = torch.ones(volume.shape[:1] + volume.shape[2:], dtype=bool)
    coords = mask.nonzero()
    feats = volume.permute(0, 2, 3, 4, 1)[mask]
    return feats, coords


def test_group_pool_hand_computed_planes():
    """All voxels occupied, M = 2, channel g * C + c = channel c of group g.

    Along Z (groups z in {0, 1}, {2, 3}): channel 0 of group g is
    100 r + 10 t + (2 g + 1), channel 1 is -(100 r + 10 t + 2 g).
    Along R (groups {0}, {1}): group g is 100 g + 10 t + z and its negation.
    Along Theta (groups t in {0, 1}, {2, 3}): 100 r + 10 (2 g + 1) + z and
    -(100 r + 10 (2 g) + z).
    """
    pool = SpatialGroupPooling(2, 3, num_groups=2)
    feats, coords = _rows(_volume())
    r, t = torch.meshgrid(torch.arange(2.), torch.arange(4.), indexing='ij')
    z_planes = pool.group_pool(feats, coords, SHAPE, 1, 0)
    assert z_planes.shape == (1, 4, 2, 4)
    for g in range(2):
        torch.testing.assert_close(z_planes[0, 2 * g],
                                   100 * r + 10 * t + 2 * g + 1)
        torch.testing.assert_close(z_planes[0, 2 * g + 1],
                                   -(100 * r + 10 * t + 2 * g))
    t2, z2 = torch.meshgrid(torch.arange(4.), torch.arange(4.), indexing='ij')
    r_planes = pool.group_pool(feats, coords, SHAPE, 1, 1)
    assert r_planes.shape == (1, 4, 4, 4)
    for g in range(2):
        torch.testing.assert_close(r_planes[0, 2 * g], 100 * g + 10 * t2 + z2)
        torch.testing.assert_close(r_planes[0, 2 * g + 1],
                                   -(100 * g + 10 * t2 + z2))
    r3, z3 = torch.meshgrid(torch.arange(2.), torch.arange(4.), indexing='ij')
    t_planes = pool.group_pool(feats, coords, SHAPE, 1, 2)
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
    plane = pool.group_pool(*_rows(_volume()), SHAPE, 1, 0)
    torch.testing.assert_close(plane[0, 0], 100 * r + 10 * t + 3)
    torch.testing.assert_close(plane[0, 1], -(100 * r + 10 * t))


def test_empty_voxels_never_win_a_group():
    """Issue 11, item 2. One Z column (r = 0, t = 0) of 4 cells, M = 1:
    cells z = 0, 1 hold -0.7 and -0.3, z = 2, 3 are empty. The group's
    maximum is over the occupied cells: max(-0.7, -0.3) = -0.3 (a dense,
    zero-filled volume gave max(-0.7, -0.3, 0, 0) = 0.0). The column
    (r = 1, t = 2) has no occupied cell at all and pools to 0; so does every
    other column. Its gradient reaches the winner (z = 1) only: 1 there, 0
    on z = 0."""
    pool = SpatialGroupPooling(1, 3, num_groups=1)
    feats = torch.tensor([[-0.7], [-0.3]], requires_grad=True)
    coords = torch.tensor([[0, 0, 0, 0], [0, 0, 0, 1]])
    plane = pool.group_pool(feats, coords, SHAPE, 1, 0)
    assert plane.shape == (1, 1, 2, 4)
    expected = torch.zeros(1, 1, 2, 4)
    expected[0, 0, 0, 0] = -0.3
    torch.testing.assert_close(plane, expected)
    plane[0, 0, 0, 0].backward()
    assert feats.grad.flatten().tolist() == [0.0, 1.0]


def test_two_groups_with_empty_cells_and_a_second_sample():
    """M = 2 along Z for sample 1 of a batch of 2: column (r = 1, t = 3)
    holds -2 at z = 0 (group 0) and -5, -4 at z = 2, 3 (group 1) -> channels
    (g = 0, g = 1) = (-2, -4); sample 0 stays all 0."""
    pool = SpatialGroupPooling(1, 3, num_groups=2)
    feats = torch.tensor([[-2.0], [-5.0], [-4.0]])
    coords = torch.tensor([[1, 1, 3, 0], [1, 1, 3, 2], [1, 1, 3, 3]])
    plane = pool.group_pool(feats, coords, SHAPE, 2, 0)
    assert plane.shape == (2, 2, 2, 4)
    assert plane[1, :, 1, 3].tolist() == [-2.0, -4.0]
    assert plane[0].abs().sum() == 0
    assert plane.abs().sum() == 6.0


def test_forward_shapes_and_backward():
    """The MLP maps M * C channels to out_channels for the (R, Theta),
    (Theta, Z), (R, Z) planes; the gradient reaches each group's maximum
    only: summing channel 0 of both Z groups puts 1 on z = 1 and z = 3 of
    each of the 2 x 4 (r, t) cells, i.e. 8 per z slice, 0 on z = 0, 2."""
    pool = SpatialGroupPooling(2, 3, num_groups=2)
    feats, coords = _rows(_volume())
    feats.requires_grad_()
    planes = pool(feats, coords, SHAPE, 1)
    assert [tuple(p.shape) for p in planes] == [(1, 3, 2, 4), (1, 3, 4, 4),
                                                (1, 3, 2, 4)]
    sum(p.sum() for p in planes).backward()
    assert pool.mlps[1][0].conv.weight.grad is not None
    feats2, coords2 = _rows(_volume())
    feats2.requires_grad_()
    pool.group_pool(feats2, coords2, SHAPE, 1, 0)[:, 0::2].sum().backward()
    grad = torch.zeros(4)
    grad.index_add_(0, coords2[:, 3], feats2.grad[:, 0])
    assert grad.tolist() == [0.0, 8.0, 0.0, 8.0]


def test_mlp_without_norm_is_pointocc_linear_relu_linear():
    """norm_cfg=None: each plane's MLP is PointOcc's Linear(M C, C_out) -
    ReLU - Linear(C_out, C_out), both with bias, no normalisation, checked
    by applying the two layers' weights to the pooled planes by hand."""
    torch.manual_seed(0)
    pool = SpatialGroupPooling(2, 3, num_groups=2, norm_cfg=None).eval()
    first, second = pool.mlps[0]
    assert first.norm_cfg is None and first.conv.bias is not None
    assert not any(isinstance(m, torch.nn.modules.batchnorm._BatchNorm)
                   for m in pool.modules())
    feats, coords = _rows(_volume())
    grouped = pool.group_pool(feats, coords, SHAPE, 1, 0)
    hidden = torch.relu(torch.einsum('oc,bchw->bohw', first.conv.weight[
        ..., 0, 0], grouped) + first.conv.bias[:, None, None])
    expected = torch.einsum('oc,bchw->bohw', second.weight[..., 0, 0],
                            hidden) + second.bias[:, None, None]
    torch.testing.assert_close(pool(feats, coords, SHAPE, 1)[0], expected)


def test_no_voxel_and_empty_batch():
    """No occupied voxel gives all-zero planes; a batch of zero samples
    zero-sized planes."""
    pool = SpatialGroupPooling(2, 3, num_groups=2).eval()
    empty = torch.zeros(0, 2), torch.zeros(0, 4, dtype=torch.long)
    assert pool.group_pool(*empty, SHAPE, 1, 0).abs().sum() == 0
    planes = pool(*empty, SHAPE, 0)
    assert planes[0].shape == (0, 3, 2, 4)


def test_bad_inputs_raise():
    """Indivisible axes, wrong channels or coordinates and a bad plane are
    named."""
    feats, coords = _rows(_volume())
    with pytest.raises(ValueError, match='not divisible into 3 groups'):
        SpatialGroupPooling(2, 3, num_groups=3).group_pool(
            feats, coords, SHAPE, 1, 0)
    pool = SpatialGroupPooling(2, 3, num_groups=2)
    with pytest.raises(ValueError, match=r'\(U, 2\)'):
        pool.group_pool(feats[:, :1], coords, SHAPE, 1, 0)
    with pytest.raises(ValueError, match=r'coordinates \(U, 4\)'):
        pool.group_pool(feats, coords[:, :3], SHAPE, 1, 0)
    with pytest.raises(ValueError, match='plane'):
        pool.group_pool(feats, coords, SHAPE, 1, 3)
    with pytest.raises(ValueError, match='num_groups'):
        SpatialGroupPooling(2, 3, num_groups=0)


def test_group_pool_writes_its_planes_in_place(monkeypatch):
    """The planes are reduced into their zero buffer in place (the
    out-of-place ``index_reduce`` first copied the buffer, the largest
    tensor of the fusion) with unchanged values and gradients: random
    voxels of two samples, two groups, float64, checked against the
    out-of-place reduction and by gradcheck."""
    gen = torch.Generator().manual_seed(2)
    mask = torch.rand(2, *SHAPE, generator=gen) < 0.5
    volume = torch.randn(2, 3, *SHAPE, generator=gen, dtype=torch.float64)
    feats, coords = _rows(volume, mask)
    feats.requires_grad_()
    pool = SpatialGroupPooling(3, 4, num_groups=2)
    expected = []
    for plane in range(3):
        pooled, (a, b) = PLANE_POOL_AXES[plane]
        group = coords[:, pooled] // (SHAPE[pooled - 1] // 2)
        cell = ((coords[:, 0] * SHAPE[a - 1] + coords[:, a]) *
                SHAPE[b - 1] + coords[:, b]) * 2 + group
        expected.append(
            feats.new_zeros(2 * SHAPE[a - 1] * SHAPE[b - 1] * 2,
                            3).index_reduce(0, cell, feats, 'amax',
                                            include_self=False))

    def out_of_place(*args, **kwargs):
        raise AssertionError('group_pool copied its plane buffer')

    monkeypatch.setattr(torch.Tensor, 'index_reduce', out_of_place)
    for plane in range(3):
        out = pool.group_pool(feats, coords, SHAPE, 2, plane)
        flat = out.permute(0, 2, 3, 1).reshape(-1, 3)
        assert torch.equal(flat, expected[plane])
        g = torch.randn(flat.shape, generator=gen, dtype=torch.float64)
        assert torch.equal(
            torch.autograd.grad(flat, feats, g)[0],
            torch.autograd.grad(expected[plane], feats, g,
                                retain_graph=True)[0])
    assert torch.autograd.gradcheck(
        lambda f: pool.group_pool(f, coords, SHAPE, 2, 0), (feats, ))


def test_recomputed_planes_are_exact():
    """``with_cp=True`` in training (float64): the three planes, the
    voxel-feature gradient, every MLP gradient and the BatchNorm
    statistics after the step equal ``with_cp=False``; each plane's MLP
    runs twice (forward and recomputation) and the pooled (R, Theta) plane
    of M * C = 4 channels x 2 x 4 cells is no longer kept for the
    backward."""
    results = []
    for with_cp in (False, True):
        torch.manual_seed(0)
        pool = SpatialGroupPooling(2, 3, num_groups=2,
                                   with_cp=with_cp).double().train()
        feats, coords = _rows(_volume().double())
        feats.requires_grad_()
        results.append(
            recorded_training_step(pool, pool.mlps[0],
                                   lambda: pool(feats, coords, SHAPE, 1),
                                   lambda: [feats.grad]))
    (plain, plain_calls, plain_packed), (cp, cp_calls, cp_packed) = results
    for a, b in zip(plain, cp):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)
    assert (plain_calls, cp_calls) == (1, 2)
    assert (2 * 4 * 2, 2) in plain_packed  # the pooled rows (a, b, M), C
    assert (2 * 4 * 2, 2) not in cp_packed
