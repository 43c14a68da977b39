"""Kernel launches and host syncs counted per module and phase
(projects/occ_common/analysis/op_counting.py) on a hand-made module."""
import torch
from torch import nn

from projects.occ_common.analysis.op_counting import OpCounter


class _Toy(nn.Module):

    def __init__(self):
        super().__init__()
        self.lin = nn.Linear(4, 3)

    def forward(self, x):
        y = self.lin(x)  # addmm (the weight's transpose is a view)
        z = y.view(-1) * 2  # view: nothing; mul
        pos = z[z > 0]  # gt; index with a bool mask: launch + sync
        z.sum().item()  # sum; _local_scalar_dense: sync only
        (z > 1).tolist()  # gt; tolist: sync only (no dispatch on CPU)
        return pos.sum() + z.sum()  # sum, sum, add


def _rows(counter):
    return {(r['module'], r['phase']): (r['launches'], r['syncs'])
            for r in counter.table()}


def test_counts_per_module_and_phase():
    """Forward of the model's own code: mul, gt, index, sum, gt, sum, sum,
    add = 8 launches; index, item, tolist = 3 syncs. ``lin`` forward: 1
    (addmm). Backward: ``lin`` computes its weight gradient (mm) and bias
    gradient (sum) = 2, the input needs none; the model's code: the bool
    index's gradient (new_zeros, then index_put with the mask: a launch
    and a sync), z's two gradients added (add) and the mul's gradient =
    4 launches, 1 sync. The backward's seed (ones_like) runs outside any
    forward or node: 1 launch in ``other``. 16 launches, 4 syncs."""
    model = _Toy()
    x = torch.randn(2, 4)
    counter = OpCounter(model)
    with counter:
        model(x).backward()
    assert _rows(counter) == {
        ('(model)', 'forward'): (8, 3),
        ('lin', 'forward'): (1, 0),
        ('(model)', 'backward'): (4, 1),
        ('lin', 'backward'): (2, 0),
        ('(outside)', 'other'): (1, 0),
    }
    assert counter.totals() == dict(launches=16, syncs=4, host_data=0)


def test_host_data_and_hooks_removed():
    """``torch.tensor([...])`` inside a forward is host data (a copy to
    the device on a GPU); after the block no hook or mode is left, so a
    second call counts nothing."""

    class _Const(nn.Module):

        def forward(self, x):
            return x + torch.tensor([1.0, 2.0])

    model = nn.Sequential(_Const())
    counter = OpCounter(model)
    with counter:
        model(torch.zeros(2))
    (row, ) = [r for r in counter.table() if r['module'] == '0']
    assert row['host_data'] == 1 and row['launches'] == 1  # add
    before = counter.totals()
    model(torch.zeros(2))
    assert counter.totals() == before
    assert not model[0]._forward_hooks and not model[0]._forward_pre_hooks


def test_repeat_interleave_syncs_only_without_output_size():
    """Its output size is the sum of the repeats: the host must read them
    unless ``output_size`` says it. Each call is two operators (the
    indices from the repeats, then an index_select): 4 launches, 1 sync."""
    repeats, x = torch.tensor([1, 2]), torch.tensor([5, 6])

    class _Repeat(nn.Module):

        def forward(self, x):
            x.repeat_interleave(repeats)
            return x.repeat_interleave(repeats, output_size=3)

    model = nn.Sequential(_Repeat())
    counter = OpCounter(model)
    with counter:
        model(x)
    assert counter.totals() == dict(launches=4, syncs=1, host_data=0)


def test_optimizer_step_counts_reads_no_sync():
    """AdamW (foreach, as torch picks for CUDA parameters) reads each
    parameter's step count, a host tensor on a GPU: inside
    ``optimizer_step`` those reads are no syncs; the same 0-dim read in
    a forward is one."""
    model = nn.Sequential(nn.Linear(2, 2))
    model(torch.ones(1, 2)).sum().backward()
    optimizer = torch.optim.AdamW(model.parameters(), foreach=True)
    counter = OpCounter(model)
    with counter:
        with counter.optimizer_step():
            optimizer.step()
        model(torch.ones(1, 2)).sum().item()
    rows = {(r['module'], r['phase']): r for r in counter.table()}
    step = rows[('(optimizer)', 'optimizer')]
    assert step['syncs'] == 0 and step['launches'] > 0
    # Two reads (the two bias corrections) for each of weight and bias.
    assert step['top_ops']['host step count read'] == 4
    assert counter.totals()['syncs'] == 1  # the .item() after the model
