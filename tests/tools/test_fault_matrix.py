"""tools/analysis_tools/fault_matrix.py and its mutation check.

The matrix feeds hostile, damaged and odd inputs to every entry point;
the mutation check breaks each guard of the library by one line (in a
forked child) and asks that some case notice. Before, 4 of 19 one-line
regressions went unnoticed because no case reached them.
"""
import multiprocessing
import os.path as osp

import pytest

from projects.occ_common.analysis.fault_cases import Case
from projects.occ_common.analysis.fault_cases_files import REAL_INFO
from projects.occ_common.analysis.fault_mutations import MUTATIONS
from projects.occ_common.analysis.source_mutation import (MutationError,
                                                          mutated_source)
from projects.occ_common.testing.tool_logs import load_tool

matrix = load_tool('tools/analysis_tools/fault_matrix.py')


def test_every_mutation_applies_and_is_listed_by_a_case():
    """Each mutation's line is in its function exactly once (a guard that
    changed shape must update its mutation), and each guard named by a
    case is a mutation and the other way round."""
    for name, mutation in MUTATIONS.items():
        source = mutated_source(*mutation)
        assert mutation.new in source, name
    listed = {guard for case in matrix.CASES for guard in case.guards}
    # Without ../shared the real-sample case, and only it, is absent.
    needs_real = set() if osp.isfile(REAL_INFO) else {'sample token checked'}
    assert listed == set(MUTATIONS) - needs_real
    assert set(matrix.testable_mutations()) == listed
    with pytest.raises(MutationError, match='0 times, not once'):
        mutated_source('projects.occ_common.fileio.safe_names:'
                       'safe_file_name', 'no such line', 'x')


def _mutated_in_child(conn):
    from projects.occ_common.analysis.source_mutation import mutate
    from projects.occ_common.engine.hooks import SafeCheckpointHook
    from projects.occ_common.evaluation import occupancy_export
    mutate('projects.occ_common.fileio.safe_names:safe_file_name',
           'if SAFE_NAME.fullmatch(text):', 'if True:')
    method = 'SafeCheckpointHook._save_checkpoint_with_step'
    mutate(f'projects.occ_common.engine.hooks.safe_checkpoint_hook:{method}',
           'if is_main_process() and osp.islink(self._pointer(runner)):',
           'if False:')
    cell = SafeCheckpointHook._save_checkpoint_with_step.__closure__[0]
    conn.send((occupancy_export.safe_file_name('../x', 'token'),
               cell.cell_contents is SafeCheckpointHook))


def test_mutate_replaces_a_function_where_it_was_imported():
    """In a child: safe_file_name mutated to accept anything is what
    occupancy_export (which imported it by name) now calls; a mutated
    method keeps its class for super(). The parent is untouched."""
    from projects.occ_common.evaluation import occupancy_export
    context = multiprocessing.get_context('fork')
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=_mutated_in_child, args=(send, ))
    child.start()
    child.join(60)
    assert receive.recv() == ('../x', True)
    with pytest.raises(ValueError, match='cannot name a file'):
        occupancy_export.safe_file_name('../x', 'token')


@pytest.mark.parametrize('inputs, expected', [
    (dict(marked=True, message='DataLoss: x'), 'code execution'),
    (dict(message='DataLoss: epoch_1.pth was changed'), 'data loss'),
    (dict(message='OK', grown=3 << 20), 'hang'),
    (dict(message='', hang=True), 'hang'),
    (dict(message='', exitcode=-11), 'segfault'),
    (dict(message='Silent: accepted'), 'silent'),
    (dict(message='OK'), 'handled'),
    (dict(message='ValueError: /tmp/f/x.pth is bad'), 'clear error'),
    (dict(message='ValueError: bad'), 'unclear error'),
])
def test_classes_worst_first(inputs, expected):
    """A 2048 MB budget: 3 GB of growth is a hang even if it loaded."""
    case = Case('c', 'clear error', None, None)
    outcome = dict(message='', hang=False, grown=0, exitcode=0,
                   marked=False)
    outcome.update(inputs)
    assert matrix._classify(case, '/tmp/f/x.pth', **outcome) == expected


#: Cases that load in the child without training or tools (~1 s each).
FAST = ('checkpoint with one flipped bit', 'NaN timestamp',
        'RayIoU origins of another data root', 'work dir named exp[1]',
        'labels.npz declaring', 'JPEG with an EXIF')


@pytest.mark.parametrize('fast', FAST)
def test_fast_cases_and_their_mutations(fast):
    """Each case ends in its expected class, and with its guard broken by
    one line (its mutation, made in the child) it does not."""
    case = next(c for c in matrix.CASES if c.name.startswith(fast))
    assert matrix.run_case(case, 60).kind == case.expected
    for guard in case.guards:
        assert matrix.run_case(case, 60, guard).kind != case.expected, guard


@pytest.mark.slow
def test_whole_matrix_is_as_expected(tmp_path):
    """Every case in its class: no code execution, data loss, silent
    result or hang, every refusal naming what it refuses."""
    result = matrix.main(['--json', str(tmp_path / 'matrix.json')])
    counts = result['counts']
    for kind in ('code execution', 'data loss', 'silent', 'hang',
                 'segfault', 'unclear error'):
        assert kind not in counts, kind
    assert sum(counts.values()) == len(matrix.CASES)


@pytest.mark.slow
def test_every_mutation_is_caught():
    """Each of the one-line regressions turns one of its cases red."""
    result = matrix.main(['--mutations'])
    assert not result['wrong'] and len(result['mutations']) == len(
        matrix.testable_mutations())


def test_an_earlier_install_does_not_hide_a_removed_guard():
    """The restricted loader installed in this process earlier (as a test
    before, or tools/test.py, does) must not stand in for the install that
    a mutation removes from init_model: each case's child starts without
    it. Before, this mutation went unnoticed in a pytest worker that had
    installed the loader (both TorchScript cases still refused clearly)."""
    from argparse import Namespace

    from projects.occ_common.fileio import install_checkpoint_loader
    install_checkpoint_loader()
    result = matrix.run_mutations(['init_model loads restricted'],
                                  Namespace(timeout=120))
    assert result['wrong'] == []
    seen = result['mutations']['init_model loads restricted']
    assert set(seen.values()) == {'unclear error'}, seen


def test_a_rank_ended_by_its_deadline_is_read_under_pytest_capture():
    """The rendezvous deadline ends a rank with os._exit from a thread; its
    one line must reach the child's stderr file even where sys.stderr is
    not file descriptor 2 (pytest's capture, a launcher's wrapper). Before,
    this case read as an unclear error inside pytest and a clear one from
    the command line."""
    result = matrix.main(['--only', 'missing distributed peer'])
    assert result['counts'] == {'clear error': 1}, result
