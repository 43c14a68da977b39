"""Tests of the graph-break and recompilation counter."""
import pytest
import torch

from projects.occ_common.analysis.compile_check import (count_recompiles,
                                                        explain_breaks,
                                                        phase_call)


def _reads_on_host(x):
    y = x * 2
    if y.sum().item() > 0:  # a host read: Dynamo breaks here
        return y + 1
    return y - 1


def test_break_is_named_with_its_line_in_this_repository():
    """One ``.item()``: two graphs, one break, reported at this file's
    line of the call with its reason."""
    report = explain_breaks(_reads_on_host, torch.ones(3))
    assert report.graphs == 2
    brk, = report.breaks
    assert brk.location.startswith(
        'tests/occ_common/analysis/test_compile_check.py:')
    assert brk.function == '_reads_on_host'
    assert 'item' in brk.code and 'item' in brk.reason.lower()
    site, = report.by_site()
    assert site['count'] == 1 and site['location'] == brk.location


def test_new_size_is_a_recompilation_and_same_size_is_not():
    """Sizes 4, 4, 6 of a function without breaks: one graph, none for
    the same size again, one (with the failed guard logged) for the new
    size under Dynamo's default static-then-dynamic rule."""
    report = count_recompiles(lambda x: x.sin() + 1,
                              [torch.ones(4), torch.ones(4), torch.ones(6)])
    assert report.graphs_per_call == [1, 0, 1]
    assert report.recompiles == 1
    assert any('size' in reason for reason in report.reasons)
    marked = torch.ones(4)
    torch._dynamo.mark_dynamic(marked, 0)
    dynamic = count_recompiles(lambda x: x.sin() + 1,
                               [marked, torch.ones(6)])
    assert dynamic.graphs_per_call == [1, 0]


def test_unknown_phase_is_refused():
    with pytest.raises(ValueError, match='phase must be one of'):
        phase_call(torch.nn.Linear(1, 1), 'export')
