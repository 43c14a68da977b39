"""Tests of densification, BEV scatter, point-voxel transfers and the
row-wise layers (batch norm, ReLU, residual block)."""
import pytest
import torch

from projects.occ_common.models.sparse import (LinearBNReLU, SparseBatchNorm,
                                               SparseReLU, SparseResBlock,
                                               SparseTensor, devoxelize,
                                               point_to_voxel,
                                               point_voxel_offsets,
                                               scatter_bev, scatter_mean,
                                               to_dense, to_dense_bev,
                                               trilinear_devoxelize,
                                               trilinear_plan, voxel_rows)
from projects.occ_common.testing.sparse_reference import \
    dense_trilinear_devoxelize


def _tensor(coords, feats, shape, batch_size=1):
    return SparseTensor(
        torch.tensor(feats, dtype=torch.float32, requires_grad=True),
        torch.tensor(coords), shape, batch_size)


def test_to_dense_and_bev_concat_layout():
    """Site (b1, z1, y0, x1) with features [a, b] = [5, 7] on a (2, 1, 2)
    grid, batch 2. Dense (B, C, Z, Y, X): [1, :, 1, 0, 1] = [5, 7].
    BEV concat: channel c * Z + z, so channel 0 * 2 + 1 = 1 holds 5 and
    channel 1 * 2 + 1 = 3 holds 7, at (y0, x1) of sample 1; 14 other zeros.
    """
    x = _tensor([[1, 1, 0, 1]], [[5., 7.]], (2, 1, 2), batch_size=2)
    dense = to_dense(x)
    assert dense.shape == (2, 2, 2, 1, 2)
    assert dense[1, :, 1, 0, 1].tolist() == [5., 7.]
    assert dense.abs().sum().item() == 12.
    bev = to_dense_bev(x)
    assert bev.shape == (2, 4, 1, 2)
    assert bev[1, :, 0, 1].tolist() == [0., 5., 0., 7.]
    assert bev.abs().sum().item() == 12.
    (bev * torch.arange(16.).view(2, 4, 1, 2)).sum().backward()
    # d/d a = weight at [1, 1, 0, 1] = 8 + 2 + 1 = 11; b at [1, 3, 0, 1] = 15
    assert x.features.grad.tolist() == [[11., 15.]]


def test_to_dense_bev_pooling_and_empty():
    """Two sites in one column (z0 and z1 at y0, x0): [1, -5] and [2, -7].
    max = [2, -5], mean = [1.5, -6], sum = [3, -12]; the other cell is 0.
    An empty tensor gives all zeros; an unknown reduction raises."""
    x = _tensor([[0, 0, 0, 0], [0, 1, 0, 0]], [[1., -5.], [2., -7.]],
                (2, 1, 2))
    expected = {'max': [2., -5.], 'mean': [1.5, -6.], 'sum': [3., -12.]}
    for reduce, values in expected.items():
        bev = to_dense_bev(x, reduce)
        assert bev.shape == (1, 2, 1, 2)
        assert bev[0, :, 0, 0].tolist() == values
        assert bev[0, :, 0, 1].tolist() == [0., 0.]
    to_dense_bev(x, 'max').sum().backward()
    # amax routes the gradient to the winning row per channel only.
    assert x.features.grad.tolist() == [[0., 1.], [1., 0.]]
    empty = SparseTensor(torch.zeros(0, 2), torch.zeros(0, 4,
                                                        dtype=torch.int),
                         (2, 1, 2), 3)
    assert to_dense_bev(empty, 'mean').abs().sum().item() == 0.
    assert to_dense_bev(empty).shape == (3, 4, 1, 2)
    with pytest.raises(ValueError, match='reduce must be one of'):
        to_dense_bev(x, 'min')
    with pytest.raises(ValueError, match="reduce must be 'max'"):
        scatter_bev(x.features, torch.zeros(2), torch.zeros(2),
                    torch.zeros(2), 1, (1, 2), 'median')


def test_scatter_mean_by_hand(code_path):
    """src [1, 3, 5] to rows [0, 0, 2] of 3: [(1 + 3) / 2, 0, 5] = [2, 0, 5].
    Each source gets gradient 1 / (count of its row): [0.5, 0.5, 1]."""
    src = torch.tensor([[1.], [3.], [5.]], requires_grad=True)
    out = scatter_mean(src, torch.tensor([0, 0, 2]), 3)
    assert out[:, 0].tolist() == [2., 0., 5.]
    out.sum().backward()
    assert src.grad[:, 0].tolist() == [0.5, 0.5, 1.]
    assert scatter_mean(src[:0], torch.zeros(0, dtype=torch.long),
                        2).tolist() == [[0.], [0.]]


def test_point_voxel_offsets_by_hand():
    """Voxels of 0.5 x 1 x 2 m (x, y, z) from the corner (-1, 0, 1).

    p0 (-0.9, 0.2, 1.5) and p1 (-0.6, 0.9, 2.5) share voxel (z, y, x) =
    (0, 0, 0), centre (-1 + 0.25, 0.5, 1 + 1) = (-0.75, 0.5, 2.0), mean
    (-0.75, 0.55, 2.0): to the mean p0 (-0.15, -0.35, -0.5) and p1 (0.15,
    0.35, 0.5); to the centre p0 (-0.15, -0.3, -0.5), p1 (0.15, 0.4, 0.5).
    p2 (0.3, 2.5, 4.0) is alone in voxel (1, 2, 2), centre (-1 + 1.25,
    2.5, 1 + 3) = (0.25, 2.5, 4.0): (0, 0, 0) and (0.05, 0, 0).
    """
    xyz = torch.tensor([[-0.9, 0.2, 1.5], [-0.6, 0.9, 2.5], [0.3, 2.5, 4.0]])
    zyx = torch.tensor([[0, 0, 0], [0, 0, 0], [1, 2, 2]])
    out = point_voxel_offsets(xyz, torch.tensor([0, 0, 1]), 2, zyx,
                              (0.5, 1.0, 2.0), (-1.0, 0.0, 1.0))
    expected = torch.tensor([[-0.15, -0.35, -0.5, -0.15, -0.3, -0.5],
                             [0.15, 0.35, 0.5, 0.15, 0.4, 0.5],
                             [0.0, 0.0, 0.0, 0.05, 0.0, 0.0]])
    torch.testing.assert_close(out, expected)


def test_voxel_rows_and_point_to_voxel():
    """Voxels x0 (row 0) and x2 (row 1) on a 4-wide line. Points in x2, x0,
    x1 (inactive) and x5 (outside) -> rows [1, 0, -1, -1]. Averaging the
    first two points' features [4, 6] gives voxel means [6, 4]."""
    x = _tensor([[0, 0, 0, 0], [0, 0, 0, 2]], [[0.], [0.]], (1, 1, 4))
    batch = torch.zeros(4, dtype=torch.long)
    zyx = torch.tensor([[0, 0, 2], [0, 0, 0], [0, 0, 1], [0, 0, 5]])
    rows = voxel_rows(x, batch, zyx)
    assert rows.tolist() == [1, 0, -1, -1]
    means = point_to_voxel(x, torch.tensor([[4.], [6.]]), rows[:2])
    assert means[:, 0].tolist() == [6., 4.]


def test_trilinear_devoxelize_by_hand(code_path):
    """Voxels x0 = 1 and x1 = 3 on a (1, 1, 3) line (x2 inactive); points
    at the voxel centre height (z = y = 0.5, weights 1 / 0 there).

    u = 1.0: halfway between centres 0.5 and 1.5 -> 0.5 * 1 + 0.5 * 3 = 2.
    u = 0.75: 0.75 * 1 + 0.25 * 3 = 1.5.
    u = 0.25: corners x-1 (outside, 0.25) and x0 (0.75) -> renormalised
    0.75 / 0.75 * 1 = 1.
    u = 2.0: corners x1 (0.5) and x2 (inactive) -> 3.
    Gradient of the sum w.r.t. voxel features = column sums of the
    weights: x0: 0.5 + 0.75 + 1 + 0 = 2.25, x1: 0.5 + 0.25 + 0 + 1 = 1.75.
    """
    x = _tensor([[0, 0, 0, 0], [0, 0, 0, 1]], [[1.], [3.]], (1, 1, 3))
    u = torch.tensor([1.0, 0.75, 0.25, 2.0])
    position = torch.stack([torch.full_like(u, 0.5),
                            torch.full_like(u, 0.5), u], dim=1)
    batch = torch.zeros(4, dtype=torch.long)
    out = trilinear_devoxelize(x, batch, position)
    torch.testing.assert_close(out[:, 0], torch.tensor([2., 1.5, 1., 3.]))
    out.sum().backward()
    torch.testing.assert_close(x.features.grad[:, 0],
                               torch.tensor([2.25, 1.75]))
    # Batches never mix: the same point in sample 1 finds no voxel.
    other = trilinear_devoxelize(x, torch.ones(1, dtype=torch.long),
                                 position[:1])
    assert other.tolist() == [[0.]]
    assert trilinear_devoxelize(x, batch[:0], position[:0]).shape == (0, 1)


def test_sparse_batch_norm_and_relu():
    """Training BN on [1, 3]: mean 2, biased variance 1, so [-1, 1] /
    sqrt(1 + eps); the running statistics (momentum 0.1) become mean
    0.9 * 0 + 0.1 * 2 = 0.2 and variance 0.9 * 1 + 0.1 * 2 = 1.1 (unbiased
    variance of [1, 3] is 2). One row in training is normalised with them,
    (5 - 0.2) / sqrt(1.1 + eps), and leaves them unchanged; zero rows give
    (0, C) and a backward that reaches the affine parameters.
    ReLU([-1, 2]) = [0, 2]."""
    norm = SparseBatchNorm(1)
    two = _tensor([[0, 0, 0, 0], [0, 0, 0, 1]], [[1.], [3.]], (1, 1, 2))
    scale = (1 + norm.bn.eps)**-0.5
    torch.testing.assert_close(norm(two).features[:, 0],
                               torch.tensor([-scale, scale]))
    before = norm.bn.running_mean.clone()
    tracked = norm.bn.num_batches_tracked.item()
    one = _tensor([[0, 0, 0, 0]], [[5.]], (1, 1, 2))
    torch.testing.assert_close(norm.bn.running_var, torch.tensor([1.1]))
    torch.testing.assert_close(
        norm(one).features[:, 0], torch.tensor([4.8 / (1.1 + 1e-5)**0.5]))
    torch.testing.assert_close(norm.bn.running_mean, before)
    assert norm.bn.num_batches_tracked.item() == tracked
    empty = SparseTensor(torch.zeros(0, 1, requires_grad=True),
                         torch.zeros(0, 4, dtype=torch.int), (1, 1, 2), 1)
    out = norm(empty).features
    assert out.shape == (0, 1)
    out.sum().backward()
    assert norm.bn.weight.grad.tolist() == [0.]
    relu = SparseReLU()(_tensor([[0, 0, 0, 0], [0, 0, 0, 1]], [[-1.], [2.]],
                                (1, 1, 2)))
    assert relu.features[:, 0].tolist() == [0., 2.]


def test_linear_bn_relu_few_rows():
    """With weight 2, bias 1 and running stats (0, 1): a single row x = 3
    in training gives ReLU(2 * 3 + 1) / sqrt(1 + eps) = 7 / sqrt(1 + eps);
    zero rows give (0, 1)."""
    mlp = LinearBNReLU(1, 1)
    with torch.no_grad():
        mlp.linear.weight.fill_(2.)
        mlp.linear.bias.fill_(1.)
    out = mlp(torch.tensor([[3.]]))
    torch.testing.assert_close(out, torch.tensor([[7. / (1 + 1e-5)**0.5]]))
    assert mlp(torch.zeros(0, 1)).shape == (0, 1)


def test_res_block_identity_when_convs_are_zero():
    """With all conv weights zero, both branches' BN see zeros and output
    their shift 0, so the block returns ReLU(x): [[-1], [2]] -> [[0], [2]].
    With a channel change the shortcut is a 1x1 conv: zero weights -> 0."""
    x = _tensor([[0, 0, 0, 0], [0, 0, 0, 1]], [[-1.], [2.]], (1, 1, 2))
    block = SparseResBlock(1, 1, indice_key='r', backend='torch')
    wider = SparseResBlock(1, 2, backend='torch')
    for module in (block, wider):
        for name, param in module.named_parameters():
            if name.endswith('conv.weight'):
                param.data.zero_()
    assert 'conv1.norm.running_mean' in block.state_dict()
    out = block(x)
    assert out.features[:, 0].tolist() == [0., 2.]
    assert wider(x).features.tolist() == [[0., 0.], [0., 0.]]
    out.features.sum().backward()
    assert x.features.grad[:, 0].tolist() == [0., 1.]


def _random_voxels(seed):
    """Two samples on a (3, 4, 5) grid, about half the sites active, and
    60 points: 50 inside the grid, 10 up to 1.5 cells outside it."""
    gen = torch.Generator().manual_seed(seed)
    shape = (3, 4, 5)
    sites = torch.nonzero(torch.rand(2, *shape, generator=gen) < 0.5)
    x = SparseTensor(
        torch.randn(len(sites), 3, generator=gen).requires_grad_(),
        sites.int(), shape, 2)
    position = torch.rand(60, 3, generator=gen) * torch.tensor(shape)
    position[50:] = torch.rand(
        10, 3, generator=gen) * (torch.tensor(shape) + 3.0) - 1.5
    batch = torch.randint(0, 2, (60, ), generator=gen)
    return x, batch, position


@pytest.mark.parametrize('seed', [0, 1])
def test_trilinear_plan_matches_dense_reference(seed, code_path):
    """The shared-lookup plan gives the dense grid's interpolation and its
    feature gradient for points in any order, inside the grid or outside
    it; every row of weights sums to 1 or (no active corner) to 0."""
    x, batch, position = _random_voxels(seed)
    ref = dense_trilinear_devoxelize(x, batch, position)
    grad_out = torch.randn_like(ref)
    ref_grad, = torch.autograd.grad(ref, x.features, grad_out)
    for order in (torch.arange(60),
                  torch.randperm(
                      60, generator=torch.Generator().manual_seed(seed))):
        plan = trilinear_plan(x, batch[order], position[order])
        out = devoxelize(x.features, plan)
        torch.testing.assert_close(out, ref[order])
        grad, = torch.autograd.grad(out, x.features, grad_out[order])
        torch.testing.assert_close(grad, ref_grad)
        sums = plan.weights.sum(dim=1)
        assert torch.all(((sums - 1).abs() < 1e-5) | (sums == 0))
        assert plan.rows.shape == (60, 8) and plan.rows.min() >= 0
    # No points.
    assert devoxelize(x.features, trilinear_plan(x, batch[:0],
                                                 position[:0])).shape == (0, 3)


def test_linear_bn_relu_eval_folds_norm_training_unchanged():
    """Eval: one folded linear layer gives ReLU(BN(Wx + b)) with the
    running statistics, and the same gradients for W, b, gamma, beta.
    Training: batch statistics, running statistics updated, as before."""
    torch.manual_seed(0)
    mlp = LinearBNReLU(5, 4)
    with torch.no_grad():
        mlp.norm.running_mean.uniform_(-1, 1)
        mlp.norm.running_var.uniform_(0.5, 2)
        mlp.norm.weight.uniform_(0.5, 1.5)
        mlp.norm.bias.uniform_(-0.5, 0.5)
    feats = torch.randn(30, 5)
    params = [
        mlp.linear.weight, mlp.linear.bias, mlp.norm.weight, mlp.norm.bias
    ]
    mlp.eval()
    ref = torch.relu(
        torch.nn.functional.batch_norm(
            mlp.linear(feats), mlp.norm.running_mean, mlp.norm.running_var,
            mlp.norm.weight, mlp.norm.bias, False, 0.0, mlp.norm.eps))
    out = mlp(feats)
    torch.testing.assert_close(out, ref)
    for got, want in zip(
            torch.autograd.grad(out.sum(), params),
            torch.autograd.grad(ref.sum(), params)):
        torch.testing.assert_close(got, want)
    mlp.train()
    mean_before = mlp.norm.running_mean.clone()
    linear = mlp.linear(feats)
    ref = torch.relu((linear - linear.mean(0)) /
                     torch.sqrt(linear.var(0, unbiased=False) + mlp.norm.eps) *
                     mlp.norm.weight + mlp.norm.bias)
    torch.testing.assert_close(mlp(feats), ref)
    torch.testing.assert_close(mlp.norm.running_mean,
                               0.9 * mean_before + 0.1 * linear.mean(0))


def test_gpu_plan_equals_the_cpu_plan():
    """The GPUs' plan (all 8 corners of every point in one search, no
    ``unique_consecutive``) has the CPU's rows and weights exactly, for
    points inside and outside the grid, grouped by cell or not."""
    from projects.occ_common.utils.device_path import forced_accelerator_path
    x, batch, position = _random_voxels(3)
    for order in (torch.argsort(batch * 10**6 + (position * 10).long().sum(
            1)), torch.arange(60)):
        with forced_accelerator_path(False):
            cpu = trilinear_plan(x, batch[order], position[order])
        with forced_accelerator_path(True):
            gpu = trilinear_plan(x, batch[order], position[order])
        assert torch.equal(gpu.weights, cpu.weights)
        assert torch.equal(gpu.rows, cpu.rows)
        assert (cpu.weights > 0).any(1).sum() > 40
