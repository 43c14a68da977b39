"""The fused lift + voxel max pool equals the naive path exactly."""
import pytest
import torch

from projects.occ_cyl.lift_pool import (LiftMaxPoolFunction, lift_max_pool,
                                        naive_lift_max_pool, voxel_max_pool)


def _dyadic_inputs(seed, num_images=3, bins=4, h=3, w=5, channels=6,
                   voxels=12):
    """Values on a 1/4 grid: products and sums are exact in float64 whatever
    the summation order, and ties are frequent."""
    gen = torch.Generator().manual_seed(seed)
    depth = torch.randint(0, 4, (num_images, bins, h, w), generator=gen) / 4
    ctx = torch.randint(-3, 4, (num_images, channels, h, w),
                        generator=gen) / 2
    idx = torch.randint(-1, voxels, (num_images, bins, h, w), generator=gen)
    return (depth.double().requires_grad_(),
            ctx.double().requires_grad_(), idx, voxels)


@pytest.mark.parametrize('chunk_size', [1, 15, 31, 10**6])
def test_fused_equals_naive_exactly_with_ties(chunk_size, code_path):
    """Values and both gradients are bitwise equal for any chunking, on
    inputs full of ties (the lowest point index wins in both paths), on
    both code paths (the GPU's backward adds a 0 for every entry without
    a winner instead of selecting those with one)."""
    depth, ctx, idx, voxels = _dyadic_inputs(0)
    fused = lift_max_pool(depth, ctx, idx, voxels, chunk_size=chunk_size)
    naive = lift_max_pool(depth, ctx, idx, voxels, fused=False)
    assert torch.equal(fused, naive)
    grad = torch.randint(-4, 5, fused.shape,
                         generator=torch.Generator().manual_seed(1)) / 8
    g_fused = torch.autograd.grad(fused, (depth, ctx), grad.double())
    g_naive = torch.autograd.grad(naive, (depth, ctx), grad.double())
    assert torch.equal(g_fused[0], g_naive[0])
    assert torch.equal(g_fused[1], g_naive[1])


def test_fused_equals_naive_on_random_floats(code_path):
    """Random float32 inputs: bitwise-equal values; gradients equal up to
    the summation order (float32 rounding)."""
    gen = torch.Generator().manual_seed(3)
    depth = torch.rand(2, 5, 4, 4, generator=gen).softmax(1)
    ctx = torch.randn(2, 7, 4, 4, generator=gen)
    idx = torch.randint(-1, 9, (2, 5, 4, 4), generator=gen)
    depth.requires_grad_()
    ctx.requires_grad_()
    fused = lift_max_pool(depth, ctx, idx, 9, chunk_size=20)
    naive = naive_lift_max_pool(depth, ctx, idx, 9)
    assert torch.equal(fused, naive)
    grad = torch.randn(fused.shape, generator=gen)
    for a, b in zip(torch.autograd.grad(fused, (depth, ctx), grad),
                    torch.autograd.grad(naive, (depth, ctx), grad)):
        torch.testing.assert_close(a, b, rtol=1e-6, atol=1e-6)


def test_hand_computed_lift_and_tie_break(code_path):
    """One image, 2 bins, 1x2 pixels, 2 channels, 2 voxels.

    depth[bin, pixel] = [[1, 0.5], [0.5, 1]], context[c, pixel] =
    [[2, 4], [-1, -2]]. Points (flat id = bin * 2 + pixel) and features:
    id 0: 1 * (2, -1) = (2, -1) -> voxel 0; id 1: 0.5 * (4, -2) = (2, -1)
    -> voxel 0; id 2: 0.5 * (2, -1) = (1, -0.5) -> voxel 1; id 3: outside.
    Voxel 0: ids 0 and 1 tie in both channels -> id 0 wins: (2, -1).
    Voxel 1: (1, -0.5).
    With grad_out all ones, only ids 0 and 2 get gradient:
    d depth[0, 0] = 2 + (-1) = 1, d depth[1, 0] = 2 - 1 = 1, the rest 0;
    d ctx[:, pixel 0] = depth[0, 0] + depth[1, 0] = 1.5 per channel,
    d ctx[:, pixel 1] = 0.
    """
    depth = torch.tensor([[[[1.0, 0.5]], [[0.5, 1.0]]]], requires_grad=True)
    ctx = torch.tensor([[[[2.0, 4.0]], [[-1.0, -2.0]]]], requires_grad=True)
    idx = torch.tensor([[[[0, 0]], [[1, -1]]]])
    for fused in (True, False):
        out = lift_max_pool(depth, ctx, idx, 2, fused=fused, chunk_size=1)
        assert out.tolist() == [[2.0, -1.0], [1.0, -0.5]]
        g_depth, g_ctx = torch.autograd.grad(out.sum(), (depth, ctx))
        assert g_depth.view(-1).tolist() == [1.0, 0.0, 1.0, 0.0]
        assert g_ctx.view(2, 2).tolist() == [[1.5, 0.0], [1.5, 0.0]]


def test_empty_voxels_and_all_outside(code_path):
    """Voxels no point reaches are 0 (even when every feature is negative)
    and receive no gradient; all points outside gives an all-zero output
    with zero gradients."""
    depth = torch.ones(1, 1, 1, 2, requires_grad=True)
    ctx = -torch.ones(1, 3, 1, 2, requires_grad=True)
    idx = torch.tensor([[[[2, 2]]]])
    out = lift_max_pool(depth, ctx, idx, 4)
    assert out.tolist() == [[0.0] * 3, [0.0] * 3, [-1.0] * 3, [0.0] * 3]
    out.sum().backward()
    # Point 0 wins all three channels of voxel 2: d depth = sum(ctx) = -3.
    assert depth.grad.view(-1).tolist() == [-3.0, 0.0]
    for fused in (True, False):
        none = lift_max_pool(depth, ctx, torch.full_like(idx, -1), 4,
                             fused=fused)
        assert torch.equal(none, torch.zeros(4, 3))
        g = torch.autograd.grad(none.sum(), (depth, ctx))
        assert not g[0].any() and not g[1].any()


def test_zero_images(code_path):
    """An empty batch of images pools to zeros."""
    depth = torch.zeros(0, 2, 2, 2, requires_grad=True)
    ctx = torch.zeros(0, 3, 2, 2, requires_grad=True)
    idx = torch.zeros(0, 2, 2, 2, dtype=torch.long)
    out = lift_max_pool(depth, ctx, idx, 5)
    assert torch.equal(out, torch.zeros(5, 3))
    out.sum().backward()
    assert depth.grad.shape == depth.shape


def test_gradcheck(code_path):
    """Numerical and analytical gradients agree (no ties, float64)."""
    gen = torch.Generator().manual_seed(5)
    depth = torch.rand(2, 3, 2, 3, generator=gen, dtype=torch.float64)
    ctx = torch.randn(2, 4, 2, 3, generator=gen, dtype=torch.float64)
    idx = torch.randint(-1, 6, (2, 3, 2, 3), generator=gen)
    depth.requires_grad_()
    ctx.requires_grad_()
    assert torch.autograd.gradcheck(
        lambda d, c: lift_max_pool(d, c, idx, 6, chunk_size=6), (depth, ctx))


def test_voxel_max_pool_hand_values(code_path):
    """Points (1, 5) and (3, 2) in voxel 1, (-4, -4) in voxel 0, one outside:
    voxel 0 = (-4, -4), voxel 1 = (3, 5), voxel 2 empty = (0, 0)."""
    feats = torch.tensor([[1.0, 5.0], [3.0, 2.0], [-4.0, -4.0], [9.0, 9.0]],
                         requires_grad=True)
    out = voxel_max_pool(feats, torch.tensor([1, 1, 0, -1]), 3)
    assert out.tolist() == [[-4.0, -4.0], [3.0, 5.0], [0.0, 0.0]]
    out.sum().backward()
    assert feats.grad.tolist() == [[0, 1], [1, 0], [1, 1], [0, 0]]


def test_bad_inputs_raise():
    """Wrong index dtype / range / shapes are named in the error."""
    depth, ctx = torch.rand(1, 2, 2, 2), torch.rand(1, 3, 2, 2)
    idx = torch.zeros(1, 2, 2, 2, dtype=torch.long)
    with pytest.raises(ValueError, match='int64'):
        lift_max_pool(depth, ctx, idx.int(), 4)
    with pytest.raises(ValueError, match=r'\[-1, 4\)'):
        lift_max_pool(depth, ctx, idx + 4, 4)
    with pytest.raises(ValueError, match='share'):
        lift_max_pool(depth, torch.rand(1, 3, 2, 3), idx, 4)
    with pytest.raises(ValueError, match='voxel_idx'):
        lift_max_pool(depth, ctx, idx[..., :1], 4)
    with pytest.raises(ValueError, match='chunk_size'):
        lift_max_pool(depth, ctx, idx, 4, chunk_size=0)


def test_single_channel_and_channels_last_context():
    """C = 1 and a channels-last (non-contiguous) context give the same
    values and gradients as the naive path."""
    depth, ctx, idx, voxels = _dyadic_inputs(7, channels=1)
    for context in (ctx, ctx.detach().to(
            memory_format=torch.channels_last).requires_grad_()):
        fused = lift_max_pool(depth, context, idx, voxels, chunk_size=16)
        naive = lift_max_pool(depth, context, idx, voxels, fused=False)
        assert torch.equal(fused, naive)
        g_fused = torch.autograd.grad(fused.sum(), (depth, context))
        g_naive = torch.autograd.grad(naive.sum(), (depth, context))
        assert torch.equal(g_fused[0], g_naive[0])
        assert torch.equal(g_fused[1], g_naive[1])


def _count_reductions(monkeypatch, method):
    """Record the ``reduce`` argument of every ``Tensor.<method>`` call."""
    calls = []
    original = getattr(torch.Tensor, method)

    def spy(self, *args, **kwargs):
        calls.append(args[3] if len(args) > 3 else kwargs.get('reduce'))
        return original(self, *args, **kwargs)

    monkeypatch.setattr(torch.Tensor, method, spy)
    return calls


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_no_grad_lift_equals_function_bitwise(seed):
    """Without a gradient the single-pass path gives the Function's values
    bitwise: on dyadic inputs full of ties, with empty voxels, under
    ``no_grad`` and for inputs that do not require grad."""
    depth, ctx, idx, voxels = _dyadic_inputs(seed, voxels=200)
    reference = LiftMaxPoolFunction.apply(depth, ctx, idx, voxels, 7)
    assert (reference == 0).all(dim=1).any()  # some voxel is empty
    with torch.no_grad():
        out = lift_max_pool(depth, ctx, idx, voxels, chunk_size=7)
    assert torch.equal(out, reference)
    out = lift_max_pool(depth.detach(), ctx.detach(), idx, voxels,
                        chunk_size=7)
    assert torch.equal(out, reference) and out.grad_fn is None


def test_no_grad_lift_runs_one_pass(monkeypatch):
    """Under ``no_grad`` the points are walked once (an ``amax`` reduction
    per chunk) and no winner pass (``amin``) runs; with a gradient both
    passes run. 3 images x 4 bins of 15 pixels in chunks of 2 bins: 6
    chunks per pass."""
    calls = _count_reductions(monkeypatch, 'index_reduce_')
    depth, ctx, idx, voxels = _dyadic_inputs(4)
    with torch.no_grad():
        lift_max_pool(depth, ctx, idx, voxels, chunk_size=30)
    assert calls == ['amax'] * 6
    calls.clear()
    lift_max_pool(depth, ctx, idx, voxels, chunk_size=30)
    assert calls == ['amax'] * 6 + ['amin'] * 6


def test_no_grad_lift_keeps_all_negative_infinity():
    """An occupied voxel whose points are all -inf in a channel pools to
    -inf in both paths (only empty voxels become 0)."""
    depth = torch.ones(1, 1, 1, 2)
    ctx = torch.tensor([[[[float('-inf'), 1.0]]]])
    idx = torch.tensor([[[[0, 2]]]])
    reference = LiftMaxPoolFunction.apply(depth, ctx, idx, 3, 4)
    with torch.no_grad():
        out = lift_max_pool(depth, ctx, idx, 3)
    assert reference.view(-1).tolist() == [float('-inf'), 0.0, 1.0]
    assert torch.equal(out, reference)


def test_no_grad_voxel_max_pool_builds_no_winners(monkeypatch):
    """Under ``no_grad`` the LiDAR max-pool gives the same values as with
    a gradient (empty voxel 0, all-negative voxel negative, outside point
    dropped) without the int64 winner scatter (no ``scatter_reduce_``)."""
    gen = torch.Generator().manual_seed(8)
    feats = torch.randn(40, 5, generator=gen)
    feats[3] = float('-inf')
    rows = torch.randint(-1, 12, (40,), generator=gen)
    rows[rows == 11] = 10  # voxel 11 stays empty
    reference = voxel_max_pool(feats.requires_grad_(), rows, 12)
    calls = _count_reductions(monkeypatch, 'scatter_reduce_')
    with torch.no_grad():
        out = voxel_max_pool(feats, rows, 12)
    assert calls == []
    assert torch.equal(out, reference.detach())
    assert out[11].tolist() == [0.0] * 5
