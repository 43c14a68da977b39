"""``cell_max``: torch's ``index_reduce`` amax, values and gradient, with a
backward that keeps far fewer temporaries."""
import importlib

import pytest
import torch

from projects.occ_common.models.layers.cell_max import cell_max
from projects.occ_common.testing.autograd_memory import peak_new_bytes

# The module (the package's ``cell_max`` attribute is the function).
cell_max_module = importlib.import_module(
    'projects.occ_common.models.layers.cell_max')


def _reference(feats, cell, num_cells):
    """The group pooling's previous code: torch's own autograd."""
    return feats.new_zeros(num_cells, feats.shape[1]).index_reduce_(
        0, cell, feats, 'amax', include_self=False)


def _case(rows=3000, channels=5, num_cells=700, seed=0):
    """Values on a coarse grid (odd multiples of 0.125 in [-2, 2], never 0:
    see the zero-maximum test) so that many rows of a cell tie at its
    maximum; some cells get no row."""
    gen = torch.Generator().manual_seed(seed)
    feats = torch.randint(-8, 8, (rows, channels), generator=gen) / 4 + 0.125
    cell = torch.randint(0, num_cells - 50, (rows, ), generator=gen)
    grad = torch.randn(num_cells, channels, generator=gen)
    return feats.double(), cell, num_cells, grad.double()


def _grad(fn, feats, cell, num_cells, grad):
    feats = feats.clone().requires_grad_()
    out = fn(feats, cell, num_cells)
    out.backward(grad)
    return out.detach(), feats.grad


def test_values_and_tie_shared_gradient_match_torch(monkeypatch):
    """Bitwise the same outputs and input gradients as index_reduce amax,
    ties included, whatever the chunking; hand case: a cell whose two rows
    tie at 1.5 gives each half of its gradient 4.0, the third row (1.0)
    none, and an unreached cell stays 0."""
    feats, cell, num_cells, grad = _case()
    at_max = feats == _reference(feats, cell, num_cells)[cell]
    reached = len(set(cell.tolist())) * feats.shape[1]
    assert int(at_max.sum()) > reached + 400  # hundreds of exact ties
    want = _grad(_reference, feats, cell, num_cells, grad)
    for chunk in (7, 1000, 1 << 16):
        monkeypatch.setattr(cell_max_module, 'CHUNK_ROWS', chunk)
        got = _grad(cell_max, feats, cell, num_cells, grad)
        assert torch.equal(got[0], want[0]) and torch.equal(got[1], want[1])

    hand = torch.tensor([[1.5], [1.0], [1.5]], requires_grad=True)
    out = cell_max(hand, torch.tensor([0, 0, 0]), 2)
    out.backward(torch.tensor([[4.0], [9.0]]))
    assert out.tolist() == [[1.5], [0.0]]
    assert hand.grad.tolist() == [[2.0], [0.0], [2.0]]


def test_a_zero_maximum_keeps_its_whole_gradient():
    """Where a cell's maximum is exactly 0, torch's index_reduce backward
    counts the initial zero of the output (which include_self=False left
    out of the maximum) as one more tie and gives the winning row only
    half; cell_max gives it all, as at every other value. Hand case: rows
    0.0 and -1.0 in one cell, gradient 6.0: torch 3.0, cell_max 6.0."""
    feats = torch.tensor([[0.0], [-1.0]])
    cell, grad = torch.tensor([0, 0]), torch.tensor([[6.0]])
    torch_grad = _grad(_reference, feats, cell, 1, grad)[1]
    assert torch_grad.tolist() == [[3.0], [0.0]]
    assert _grad(cell_max, feats, cell, 1, grad)[1].tolist() == [[6.0], [0.0]]


def test_gradcheck():
    """Distinct values (no ties): the analytic gradient is the numeric
    one."""
    gen = torch.Generator().manual_seed(1)
    feats = torch.randn(40, 3, generator=gen, dtype=torch.double)
    cell = torch.randint(0, 12, (40, ), generator=gen)
    assert torch.autograd.gradcheck(
        lambda f: cell_max(f, cell, 15), (feats.requires_grad_(), ))


def test_backward_keeps_fewer_temporaries(monkeypatch):
    """The backward's peak of new tensors: torch's formula holds about four
    output-sized and four input-sized temporaries at once; this one the
    shared gradient (output-sized) and the returned gradient, plus chunks.
    With 3000 x 5 inputs and 700 x 5 outputs in float64 that is
    ~(700 + 3000) * 40 B = 148 kB plus 64-row chunks against ~4 x that."""
    monkeypatch.setattr(cell_max_module, 'CHUNK_ROWS', 64)
    feats, cell, num_cells, grad = _case()
    peaks = {}
    for name, fn in (('torch', _reference), ('cell_max', cell_max)):
        leaf = feats.clone().requires_grad_()
        out = fn(leaf, cell, num_cells)
        _, peaks[name] = peak_new_bytes(lambda: out.backward(grad))
    floor = (num_cells + feats.shape[0]) * feats.shape[1] * 8
    assert peaks['cell_max'] < 1.2 * floor
    assert peaks['torch'] > 3 * floor


def test_no_graph_without_grad_and_bad_shapes():
    feats = torch.randn(4, 2, requires_grad=True)
    with torch.no_grad():
        assert cell_max(feats, torch.tensor([0, 1, 1, 0]), 2).grad_fn is None
    with pytest.raises(ValueError, match='feats'):
        cell_max(feats, torch.tensor([0, 1]), 2)
