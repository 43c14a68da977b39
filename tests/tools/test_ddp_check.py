"""tools/analysis_tools/ddp_check.py: the summary, the table and the exit
status (the DDP runs themselves: tests/test_paper_configs_ddp.py)."""
import json

import pytest

from projects.occ_common.testing.tool_logs import load_tool


def _tool():
    return load_tool('tools/analysis_tools/ddp_check.py')


def _rank(rank, unused=(), error=None, losses=(2.0, 1.5), diff=0.0):
    return dict(config='a.py', rank=rank, backend='gloo', losses=list(losses),
                unused=list(unused), error=error, iter_s=[3.0, 2.5],
                max_param_diff_from_rank0=diff)


def test_a_clean_run_exits_0_and_writes_json(monkeypatch, tmp_path,
                                             capsys):
    tool = _tool()
    seen = {}

    def fake(jobs, **kwargs):
        seen.update(kwargs, jobs=jobs)
        return [[_rank(0), _rank(1, losses=(2.1, 1.4))]]

    monkeypatch.setattr(tool, 'ddp_check', fake)
    out = tmp_path / 'ddp.json'
    assert tool.main(['a.py', '--device', 'cpu', '--amp', 'bf16',
                      '--json', str(out)]) == 0
    assert seen['ranks'] == 2 and seen['iters'] == 2
    assert seen['amp'] == 'bf16' and seen['num_points'] is None
    assert seen['jobs'] == [dict(config='a.py', options=None,
                                 batch_size=None)]
    (row, ) = json.loads(out.read_text())['configs']
    assert row['ok'] and row['unused'] == [] and row['error'] is None
    assert row['losses'] == [[2.0, 1.5], [2.1, 1.4]]
    text = capsys.readouterr().out
    assert 'ok     a.py (2 ranks, gloo, amp bf16)' in text
    assert 'last loss per rank 1.5000, 1.4000' in text
    assert 'seconds a step (rank 0) 3.00, 2.50' in text


def test_unused_parameters_or_an_error_exit_1(monkeypatch, capsys):
    """The pre-issue-45 SDG failure, as the ranks report it."""
    tool = _tool()
    message = ('RuntimeError: Expected to have finished reduction in the '
               'prior iteration before starting a new one.')
    names = ['img_neck.fpn_convs.1.conv.bias',
             'img_neck.fpn_convs.1.conv.weight']
    monkeypatch.setattr(
        tool, 'ddp_check', lambda jobs, **kw: [[
            _rank(0, names, message, losses=(2.0, )),
            _rank(1, names, message, losses=(2.1, ))
        ]])
    assert tool.main(['a.py', '--device', 'cpu']) == 1
    text = capsys.readouterr().out
    assert 'FAILED a.py' in text
    assert 'error: RuntimeError: Expected to have finished' in text
    assert f'no gradient: {names[0]}, {names[1]}' in text


def test_bad_counts_are_refused():
    with pytest.raises(SystemExit):
        _tool().parse_args(['a.py', '--ranks', '0'])
