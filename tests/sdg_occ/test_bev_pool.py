"""Tests of the vectorised BEV pooling against a naive scatter loop."""
import math

import pytest
import torch

from projects.sdg_occ import (BEVPoolIndexCache, bev_pool, bev_pool_indices,
                              bev_pool_mask)

# A 4 x 4 BEV (Y, X) over x, y in [-2, 2) and z in [-1, 1): 1 m cells.
PC_RANGE = (-2.0, -2.0, -1.0, 2.0, 2.0, 1.0)
BEV_SHAPE = (4, 4)


def _naive_pool(coords, batch_index, feat_index, weights, feats, batch_size):
    """Reference: loop over points, scatter weight * feature by hand."""
    out = torch.zeros(batch_size, feats.shape[1], *BEV_SHAPE)
    mask = torch.zeros(batch_size, 1, *BEV_SHAPE, dtype=torch.bool)
    for p in range(coords.shape[0]):
        x, y, z = (float(v) for v in coords[p])
        ix = math.floor((x - PC_RANGE[0]) / 1.0)
        iy = math.floor((y - PC_RANGE[1]) / 1.0)
        if not (0 <= ix < 4 and 0 <= iy < 4 and -1.0 <= z < 1.0):
            continue
        b = int(batch_index[p])
        out[b, :, iy, ix] += weights[p] * feats[feat_index[p]]
        mask[b, 0, iy, ix] = True
    return out, mask


def test_hand_made_points(code_path):
    """Three points, 2 channels, batch 1.

    p0 (0.5, -1.5, 0) -> cell x = floor(2.5) = 2, y = floor(0.5) = 0, weight
    2 on feature (1, 10); p1 (0.9, -1.1, 0.9) -> same cell, weight 1 on
    feature (3, 30): cell (y=0, x=2) = (2*1 + 3, 2*10 + 30) = (5, 50).
    p2 at x = 2.0 (the upper x edge) and p3 at z = 1.0 are outside.
    p4 (-2.0, 1.99, -1.0) sits on the lower edges -> cell (y=3, x=0) with
    weight 0.5 on feature (1, 10) = (0.5, 5).
    """
    coords = torch.tensor([[0.5, -1.5, 0.0], [0.9, -1.1, 0.9],
                           [2.0, 0.0, 0.0], [0.0, 0.0, 1.0],
                           [-2.0, 1.99, -1.0]])
    feats = torch.tensor([[1.0, 10.0], [3.0, 30.0]], requires_grad=True)
    feat_index = torch.tensor([0, 1, 0, 0, 0])
    weights = torch.tensor([2.0, 1.0, 5.0, 5.0, 0.5], requires_grad=True)
    idx = bev_pool_indices(coords, torch.zeros(5, dtype=torch.long),
                           feat_index, 1, PC_RANGE, BEV_SHAPE)
    # The CPU's path keeps the pooled points, sorted by cell; the GPUs'
    # keeps all five and sends p2 and p3 to the drop cell 1 * 4 * 4 = 16.
    assert idx.bev_index.tolist() == ([2, 2, 12] if code_path == 'cpu path'
                                      else [2, 2, 16, 16, 12])
    assert int(idx.num_pooled()) == 3
    bev = bev_pool(feats, weights, idx)
    expected = torch.zeros(1, 2, 4, 4)
    expected[0, :, 0, 2] = torch.tensor([5.0, 50.0])
    expected[0, :, 3, 0] = torch.tensor([0.5, 5.0])
    assert torch.allclose(bev, expected)
    mask = bev_pool_mask(idx)
    assert mask.sum() == 2 and mask[0, 0, 0, 2] and mask[0, 0, 3, 0]
    bev.sum().backward()
    # d/dw_p = sum of feature p = 11 (p0, p4) or 33 (p1); dropped points 0.
    assert torch.allclose(weights.grad,
                          torch.tensor([11.0, 33.0, 0.0, 0.0, 11.0]))
    # d/dfeat_0 = 2 + 0.5 (p0, p4), d/dfeat_1 = 1 (p1), both channels.
    assert torch.allclose(feats.grad, torch.tensor([[2.5, 2.5], [1.0, 1.0]]))


def test_matches_naive_scatter_loop(code_path):
    """60 random points over two samples, some outside the range."""
    gen = torch.Generator().manual_seed(0)
    coords = torch.rand(60, 3, generator=gen) * torch.tensor(
        [5.0, 5.0, 2.6]) - torch.tensor([2.5, 2.5, 1.3])
    batch_index = torch.randint(0, 2, (60, ), generator=gen)
    feat_index = torch.randint(0, 7, (60, ), generator=gen)
    weights = torch.rand(60, generator=gen)
    feats = torch.randn(7, 3, generator=gen)
    idx = bev_pool_indices(coords, batch_index, feat_index, 2, PC_RANGE,
                           BEV_SHAPE)
    ref, ref_mask = _naive_pool(coords, batch_index, feat_index, weights,
                                feats, 2)
    assert torch.allclose(bev_pool(feats, weights, idx), ref, atol=1e-6)
    assert torch.equal(bev_pool_mask(idx), ref_mask)
    if code_path == 'cpu path':
        assert torch.all(idx.bev_index[1:] >= idx.bev_index[:-1])


def test_weight_index_and_select(code_path):
    """An explicit weight index picks weights[3] = 4 for the only point;
    select() with an all-false mask leaves an empty, all-zero pool."""
    idx = bev_pool_indices(
        torch.tensor([[0.5, 0.5, 0.0]]), torch.tensor([0]),
        torch.tensor([0]), 1, PC_RANGE, BEV_SHAPE,
        weight_index=torch.tensor([3]))
    feats = torch.ones(1, 1)
    bev = bev_pool(feats, torch.tensor([1.0, 2.0, 3.0, 4.0]), idx)
    assert bev[0, 0, 2, 2] == 4.0 and bev.sum() == 4.0
    empty = idx.select(torch.tensor([False]))
    assert bev_pool(feats, torch.ones(4), empty).abs().sum() == 0


def test_empty_points_backward(code_path):
    """No point: zero BEV, empty mask, zero gradient on the features."""
    feats = torch.randn(4, 2, requires_grad=True)
    idx = bev_pool_indices(
        torch.zeros(0, 3), torch.zeros(0, dtype=torch.long),
        torch.zeros(0, dtype=torch.long), 2, PC_RANGE, BEV_SHAPE)
    bev = bev_pool(feats, torch.zeros(0), idx)
    assert bev.shape == (2, 2, 4, 4) and bev.abs().sum() == 0
    assert not bev_pool_mask(idx).any()
    bev.sum().backward()
    assert torch.equal(feats.grad, torch.zeros(4, 2))


def test_index_cache_reuses_indices_per_geometry():
    """Same key -> one computation; a changed matrix -> recomputed."""
    cache = BEVPoolIndexCache()
    calls = []

    def compute():
        calls.append(1)
        return bev_pool_indices(
            torch.zeros(1, 3), torch.zeros(1, dtype=torch.long),
            torch.zeros(1, dtype=torch.long), 1, PC_RANGE, BEV_SHAPE)

    mat = torch.eye(4)
    first = cache.get((mat, (8, 8)), compute)
    second = cache.get((mat.clone(), (8, 8)), compute)
    assert first is second and len(calls) == 1
    assert cache.hits == 1 and cache.misses == 1
    cache.get((mat * 2, (8, 8)), compute)
    cache.get((mat * 2, (4, 8)), compute)
    assert len(calls) == 3 and cache.misses == 3


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match=r'coords must have shape'):
        bev_pool_indices(
            torch.zeros(2, 2), torch.zeros(2), torch.zeros(2), 1, PC_RANGE,
            BEV_SHAPE)
    with pytest.raises(ValueError, match='point_cloud_range'):
        bev_pool_indices(
            torch.zeros(2, 3), torch.zeros(2), torch.zeros(2), 1,
            PC_RANGE[:4], BEV_SHAPE)


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs CUDA')
def test_cuda_matches_cpu():
    gen = torch.Generator().manual_seed(1)
    coords = torch.rand(50, 3, generator=gen) * 4 - 2
    batch_index = torch.randint(0, 2, (50, ), generator=gen)
    feat_index = torch.randint(0, 5, (50, ), generator=gen)
    weights = torch.rand(50, generator=gen)
    feats = torch.randn(5, 3, generator=gen)
    ref = bev_pool(feats, weights,
                   bev_pool_indices(coords, batch_index, feat_index, 2,
                                    PC_RANGE, BEV_SHAPE))
    idx = bev_pool_indices(coords.cuda(), batch_index.cuda(),
                           feat_index.cuda(), 2, PC_RANGE, BEV_SHAPE)
    out = bev_pool(feats.cuda(), weights.cuda(), idx)
    assert torch.allclose(out.cpu(), ref, atol=1e-5)
