"""Tests of eager islands: data-sized steps inside compiled code."""
import torch

from projects.occ_common.analysis.compile_check import (count_recompiles,
                                                        explain_breaks)
from projects.occ_common.utils.eager_island import eager_island


def _positive(x):
    """The positive entries: as many as the data has."""
    return x[x > 0]


def _after(select):
    def fn(x):
        kept = select(x * 1.0)  # an operator before it: a graph to break
        return kept * 2 + 1, x.sin()

    return fn


# Eight values each, 3 and then 5 of them positive.
_FEW = torch.tensor([1.0, -1, 2, -2, 3, -3, -4, -5])
_MORE = torch.tensor([1.0, -1, 2, -2, 3, 4, 5, -5])


def test_island_is_one_break_and_its_size_compiles_once():
    """A boolean selection traced by Dynamo breaks the graph and the graph
    after it takes the selection as an input of fixed size: a second
    sample with another count (5 instead of 3) compiles it again. As an
    eager island the selection is one break too, but its output's size is
    marked dynamic: the second sample compiles nothing, and the values
    are eager's ((1, 2, 3) * 2 + 1 = (3, 5, 7))."""
    plain = count_recompiles(_after(_positive), [_FEW, _MORE])
    island = count_recompiles(_after(eager_island(_positive)), [_FEW, _MORE])
    assert plain.recompiles >= 1
    assert island.recompiles == 0
    assert len(explain_breaks(_after(eager_island(_positive)),
                              _FEW).breaks) == 1
    compiled = torch.compile(_after(eager_island(_positive)),
                             backend='eager')
    for x in (_FEW, _MORE):
        kept, sines = compiled(x)
        assert torch.equal(kept, x[x > 0] * 2 + 1)
        assert torch.equal(sines, x.sin())
    assert compiled(_FEW)[0].tolist() == [3.0, 5.0, 7.0]


def test_fixed_size_island_marks_nothing_and_changes_nothing_eagerly():
    """``dynamic_dim=None`` returns the outputs unmarked; outside
    torch.compile an island is the function itself (same values, lists
    and tuples passed through)."""
    def pair(x):
        return [x + 1, (x * 2, x[:1])]

    island = eager_island(dynamic_dim=None)(pair)
    out = island(torch.tensor([1.0, 2.0]))
    assert out[0].tolist() == [2.0, 3.0]
    assert out[1][0].tolist() == [2.0, 4.0] and out[1][1].tolist() == [1.0]
    assert not hasattr(out[0], '_dynamo_weak_dynamic_indices')
    marked = eager_island(pair)(torch.tensor([1.0, 2.0]))
    assert marked[0]._dynamo_weak_dynamic_indices == {0}
    assert eager_island(_positive)(_FEW).tolist() == [1.0, 2.0, 3.0]
