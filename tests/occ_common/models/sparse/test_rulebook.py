"""Tests of the sparse tensor type and the vectorised rulebooks."""
import pytest
import torch

from projects.occ_common.models.sparse import (CoordIndex, SparseTensor,
                                               conv_output_shape, delinearize,
                                               linearize, strided_rulebook,
                                               submanifold_rulebook)


def _line_coords(xs, batch=0):
    """Sites on a (Z, Y, X) = (1, 1, X) line, as (batch, 0, 0, x) rows."""
    return torch.tensor([[batch, 0, 0, x] for x in xs], dtype=torch.int32)


def _pairs(rulebook):
    """Per offset, the sorted list of (input row, output row) pairs."""
    return [
        sorted(zip(i.tolist(), o.tolist()))
        for i, o in zip(rulebook.in_indices, rulebook.out_indices)
    ]


def test_linearize_round_trip():
    """Keys are ((b * Z + z) * Y + y) * X + x on a (2, 3, 4) grid.

    (1, 1, 2, 3): ((1 * 2 + 1) * 3 + 2) * 4 + 3 = (9 + 2) * 4 + 3 = 47.
    (0, 0, 0, 1): 1.
    """
    coords = torch.tensor([[1, 1, 2, 3], [0, 0, 0, 1]], dtype=torch.int32)
    keys = linearize(coords[:, 0], coords[:, 1:], (2, 3, 4))
    assert keys.tolist() == [47, 1]
    assert torch.equal(delinearize(keys, (2, 3, 4)), coords)


def test_coord_index_query_and_empty():
    """Keys [7, 2, 9] sort to [2, 7, 9]; 9 is row 2, 2 is row 1, 5 absent.

    An empty index answers -1 for every query.
    """
    index = CoordIndex(torch.tensor([7, 2, 9]))
    assert index.query(torch.tensor([9, 2, 5, 7])).tolist() == [2, 1, -1, 0]
    empty = CoordIndex(torch.zeros(0, dtype=torch.long))
    assert empty.query(torch.tensor([3, 4])).tolist() == [-1, -1]
    assert index.query(torch.zeros(0, dtype=torch.long)).numel() == 0


def test_coord_index_query_run():
    """Keys [9, 2, 5, 3] are rows 0-3. Runs of 3 consecutive keys:
    1, 2, 3 -> [-1, 1, 3]; 2, 3, 4 -> [1, 3, -1]; 4, 5, 6 -> [-1, 2, -1];
    8, 9, 10 -> [-1, 0, -1]; 9, 10, 11 -> [0, -1, -1] (past the end).
    Each equals a separate query of start + j."""
    index = CoordIndex(torch.tensor([9, 2, 5, 3]))
    start = torch.tensor([1, 2, 4, 8, 9])
    runs = index.query_run(start, 3)
    assert torch.stack(runs, dim=1).tolist() == [[-1, 1, 3], [1, 3, -1],
                                                 [-1, 2, -1], [-1, 0, -1],
                                                 [0, -1, -1]]
    for j, rows in enumerate(runs):
        assert torch.equal(rows, index.query(start + j))
    empty = CoordIndex(torch.zeros(0, dtype=torch.long))
    assert [r.tolist() for r in empty.query_run(start[:2], 2)] == [[-1, -1],
                                                                   [-1, -1]]


def test_sparse_tensor_validation():
    """Wrong shapes, float coords and out-of-grid sites raise ValueError."""
    feats = torch.zeros(2, 3)
    coords = _line_coords([0, 3])
    x = SparseTensor(feats, coords, (1, 1, 4), 1)
    assert (x.num_voxels, x.num_channels) == (2, 3)
    assert x.coords.dtype == torch.int32
    with pytest.raises(ValueError, match='features of shape'):
        SparseTensor(torch.zeros(2), coords, (1, 1, 4), 1)
    with pytest.raises(ValueError, match='coords of shape'):
        SparseTensor(feats, coords[:, :3], (1, 1, 4), 1)
    with pytest.raises(ValueError, match='integer coords'):
        SparseTensor(feats, coords.float(), (1, 1, 4), 1)
    with pytest.raises(ValueError, match='2 feature rows but 1'):
        SparseTensor(feats, coords[:1], (1, 1, 4), 1)
    with pytest.raises(ValueError, match=r'column x spans \[0, 3\]'):
        SparseTensor(feats, coords, (1, 1, 3), 1)
    with pytest.raises(ValueError, match='column batch'):
        SparseTensor(feats, _line_coords([0, 1], batch=1), (1, 1, 4), 1)
    with pytest.raises(ValueError, match='batch_size >= 1'):
        SparseTensor(feats, coords, (1, 1, 4), 0)
    with pytest.raises(ValueError, match='replace_feature'):
        x.replace_feature(torch.zeros(3, 3))
    empty = SparseTensor(
        torch.zeros(0, 3), torch.zeros(0, 4, dtype=torch.long), (1, 1, 4), 2)
    assert empty.num_voxels == 0


def test_submanifold_rulebook_line():
    """Kernel (1, 1, 3) on sites b0:x0, b0:x1, b0:x3 and b1:x1 (rows 0-3).

    Output q reads input q + (k - 1):
    k=0 (dx=-1): row 1 (x1) reads x0 = row 0; x0 reads x-1 (outside);
    x3 reads x2 (inactive); b1:x1 reads b1:x0 (inactive, batches never mix).
    k=1: identity on all four rows.
    k=2 (dx=+1): row 0 (x0) reads x1 = row 1; x1 reads x2 (inactive);
    x3 reads x4 (outside); b1:x1 reads b1:x2 (inactive).
    """
    coords = torch.cat([_line_coords([0, 1, 3]), _line_coords([1], 1)])
    rulebook = submanifold_rulebook(coords, (1, 1, 4), (1, 1, 3), (1, 1, 1))
    assert rulebook.center == 1
    assert _pairs(rulebook) == [[(0, 1)], [(0, 0), (1, 1), (2, 2), (3, 3)],
                                [(1, 0)]]
    assert rulebook.num_pairs == 6
    assert torch.equal(rulebook.out_coords, coords)


def test_submanifold_rulebook_dilation_and_even_kernel():
    """Dilation 2 on sites x0, x2, x3: k=0 reads q - 2, k=2 reads q + 2.

    k=0: x2 reads x0 -> (0, 1); x3 reads x1 (inactive).
    k=2: x0 reads x2 -> (1, 0); x2 reads x4 (outside).
    """
    coords = _line_coords([0, 2, 3])
    rulebook = submanifold_rulebook(coords, (1, 1, 5), (1, 1, 3), (1, 1, 2))
    assert _pairs(rulebook)[0] == [(0, 1)]
    assert _pairs(rulebook)[2] == [(1, 0)]
    with pytest.raises(ValueError, match='odd kernel_size'):
        submanifold_rulebook(coords, (1, 1, 5), (1, 1, 2), (1, 1, 1))


def test_strided_rulebook_kernel_two():
    """Kernel = stride = 2 along x on sites x0, x1, x3 of a 4-wide line.

    q = floor(x / 2): x0 (k=0) and x1 (k=1) -> q0; x3 (k=1) -> q1.
    Output shape (4 - 2) // 2 + 1 = 2.
    """
    coords = _line_coords([0, 1, 3])
    rulebook = strided_rulebook(coords, (1, 1, 4), (1, 1, 2), (1, 1, 2),
                                (0, 0, 0), (1, 1, 1))
    assert rulebook.out_shape == (1, 1, 2)
    assert rulebook.out_coords.tolist() == [[0, 0, 0, 0], [0, 0, 0, 1]]
    assert _pairs(rulebook) == [[(0, 0)], [(1, 0), (2, 1)]]


def test_strided_rulebook_kernel_three_dilates_active_set():
    """Kernel 3, stride 2, padding 1 along x on sites x1, x2 of width 5.

    Output shape (5 + 2 - 2 - 1) // 2 + 1 = 3. Output q reads
    p = 2q - 1 + k:
    x1: k=0 -> q=1, k=2 -> q=0 (k=1 gives 2q = 1, not integer);
    x2: k=1 -> q=1 only.
    So x1 feeds two outputs (the active set dilates) and the inverse
    rulebook maps them back onto x1 and x2.
    """
    coords = _line_coords([1, 2])
    rulebook = strided_rulebook(coords, (1, 1, 5), (1, 1, 3), (1, 1, 2),
                                (0, 0, 1), (1, 1, 1))
    assert rulebook.out_shape == (1, 1, 3)
    assert rulebook.out_coords[:, 3].tolist() == [0, 1]
    assert _pairs(rulebook) == [[(0, 1)], [(1, 1)], [(0, 0)]]
    inverse = rulebook.inverted()
    assert _pairs(inverse) == [[(1, 0)], [(1, 1)], [(0, 0)]]
    assert inverse.out_shape == (1, 1, 5)
    assert torch.equal(inverse.out_coords, coords)


def test_rulebooks_empty_input():
    """No sites: every offset has zero pairs and there is no output site."""
    coords = torch.zeros(0, 4, dtype=torch.int32)
    subm = submanifold_rulebook(coords, (2, 2, 2), (3, 3, 3), (1, 1, 1))
    strided = strided_rulebook(coords, (2, 2, 2), (2, 2, 2), (2, 2, 2),
                               (0, 0, 0), (1, 1, 1))
    assert subm.num_pairs == 0 and len(subm.in_indices) == 27
    assert strided.num_pairs == 0
    assert strided.out_coords.shape == (0, 4)
    assert strided.out_shape == (1, 1, 1)


def test_conv_output_shape():
    """(64 + 2 * 1 - 1 * (3 - 1) - 1) // 2 + 1 = 32; a kernel larger than
    the grid leaves no site and raises."""
    assert conv_output_shape((64, 8, 5), (3, 2, 1), (2, 2, 1), (1, 0, 0),
                             (1, 1, 1)) == (32, 4, 5)
    with pytest.raises(ValueError, match='leaves no output site'):
        conv_output_shape((2, 2, 2), (3, 3, 3), (1, 1, 1), (0, 0, 0),
                          (1, 1, 1))
