"""Fault matrix of the loaders, tools and runs, one child a case.

Every case writes an input as users meet it or attackers write it (a
download, a file planted in a work dir or torch hub's cache, a damaged
copy, a FIFO, a second run, a missing peer, a valid file) and feeds it to
one entry point of the library in a forked child process. The outcome is
classed (``projects/occ_common/analysis/fault_cases.py``):

* ``code execution``: the payload's marker file appeared;
* ``data loss``: a file the case does not own was changed or lost;
* ``silent``: a wrong input or result was accepted without a word;
* ``hang``: the child ran past its time or memory budget;
* ``segfault``: the child died of a signal;
* ``unclear error``: an error that does not name what the case expects
  (the file; the rank and address);
* ``clear error``: refused, naming it;
* ``handled``: a valid input loaded, or an odd one handled correctly.

Usage::

    python tools/analysis_tools/fault_matrix.py [--only TEXT] [--timeout S]
        [--mutations [NAME ...]] [--json OUT.json]

prints a line a case and the count of each class, and exits with status 1
if a case's class is not the one it expects. ``--mutations`` runs the
mutation check instead (``projects/occ_common/analysis/fault_mutations.py``):
for each one-line regression of a guard, the cases that list it run with
it made in the child, and at least one must leave its expected class;
exit status 1 if a mutation goes unnoticed.
"""
import argparse
import collections
import glob
import json
import multiprocessing
import os
import os.path as osp
import resource
import sys
import tempfile
import time
from typing import Dict, List, NamedTuple, Optional

from projects.occ_common.analysis.fault_cases import Case
from projects.occ_common.analysis.fault_cases_files import FILE_CASES
from projects.occ_common.analysis.fault_cases_inputs import INPUT_CASES
from projects.occ_common.analysis.fault_cases_runs import RUN_CASES
from projects.occ_common.analysis.fault_mutations import MUTATIONS
from projects.occ_common.fileio.checkpoint_schemes import \
    uninstall_checkpoint_loader

#: Every case, in the order printed.
CASES: List[Case] = FILE_CASES + RUN_CASES + INPUT_CASES


class Outcome(NamedTuple):
    """A case's class and the child's message (its error, ``'OK'``)."""
    kind: str
    message: str


def _resident_kb(pid: int) -> int:
    """Resident memory of process ``pid`` in kB (0 if unknown)."""
    try:
        with open(f'/proc/{pid}/statm') as f:
            return int(f.read().split()[1]) * os.sysconf('SC_PAGE_SIZE') \
                // 1024
    except (OSError, ValueError, IndexError):
        return 0


def _child(case: Case, path: str, conn, folder: str,
           mutation: Optional[str]) -> None:
    """Load in the child, its output to files; send the outcome and the
    growth of its peak resident memory (kB)."""
    for fd, name in ((1, 'stdout'), (2, 'stderr')):
        out = os.open(osp.join(folder, f'child.{name}'),
                      os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(out, fd)
    # Python-level writes to the files too (the parent's sys.stdout may be
    # another object, e.g. pytest's capture).
    sys.stdout = open(1, 'w', buffering=1, closefd=False)
    sys.stderr = open(2, 'w', buffering=1, closefd=False)
    start = _resident_kb(os.getpid())
    # Each case starts as a fresh process would: without the restricted
    # loader that a test or case before it installed in the parent.
    uninstall_checkpoint_loader()
    try:
        if mutation is not None:
            from projects.occ_common.analysis.source_mutation import mutate
            mutate(*MUTATIONS[mutation])
        loaded = case.load(path)
        repr(loaded)  # reading a forged array is what crashes
        message = 'OK'
    except BaseException as err:  # noqa: BLE001 - SystemExit included
        message = f'{type(err).__name__}: {err}'
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    conn.send((message, peak - start))


def _last_line(path: str) -> str:
    try:
        with open(path, errors='replace') as f:
            lines = [line.strip() for line in f if line.strip()]
    except OSError:
        return ''
    return lines[-1] if lines else ''


def run_case(case: Case, timeout: float,
             mutation: Optional[str] = None) -> Outcome:
    """The class of ``case``'s outcome (see the module docstring), with
    ``mutation`` (a name of ``MUTATIONS``) made in the child."""
    context = multiprocessing.get_context('fork')
    timeout = case.timeout or timeout
    with tempfile.TemporaryDirectory() as folder:
        marker = osp.join(folder, 'marker')
        path = case.make(folder, marker)
        receive, send = context.Pipe(duplex=False)
        child = context.Process(
            target=_child, args=(case, path, send, folder, mutation))
        child.start()
        base = _resident_kb(child.pid)
        deadline, hang = time.time() + timeout, False
        while child.is_alive() and not hang:
            child.join(0.05)
            grown = _resident_kb(child.pid) - base
            hang = time.time() > deadline or grown > case.memory_mb * 1024
        if child.is_alive():
            child.kill()
            child.join()
        message, grown = receive.recv() if receive.poll() else ('', 0)
        message = message or _last_line(osp.join(folder, 'child.stderr'))
        return Outcome(
            _classify(case, path, message, hang, grown, child.exitcode,
                      osp.exists(marker) or glob.glob(
                          osp.join(glob.escape(folder), '**', 'marker'),
                          recursive=True)), message)


def _classify(case: Case, path: str, message: str, hang: bool, grown: int,
              exitcode: Optional[int], marked: bool) -> str:
    """The class of an outcome, the worst that applies."""
    if marked:
        return 'code execution'
    if message.startswith('DataLoss:'):
        return 'data loss'
    if hang or grown > case.memory_mb * 1024 or message.startswith(
            'MemoryError'):
        return 'hang'
    if exitcode and exitcode < 0:
        return 'segfault'
    if message.startswith('Silent:'):
        return 'silent'
    if message == 'OK':
        return 'handled'
    wanted = case.names(path) if case.names else [osp.basename(path)]
    return 'clear error' if message and all(
        text in message for text in wanted) else 'unclear error'


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--only', help='run the cases whose name has TEXT')
    parser.add_argument(
        '--timeout', type=float, default=120, help='seconds a case')
    parser.add_argument(
        '--mutations',
        nargs='*',
        help='run the mutation check (of the named mutations; all if none '
        'is named) instead of the matrix')
    parser.add_argument('--json', help='also write the outcomes here')
    parser.add_argument(
        '--verbose', action='store_true', help='print each case\'s message')
    return parser.parse_args(argv)


def run_matrix(args) -> Dict:
    """Run the cases; print each outcome and the counts per class."""
    counts, outcomes, wrong = collections.Counter(), {}, []
    for case in CASES:
        if args.only and args.only not in case.name:
            continue
        outcome, message = run_case(case, args.timeout)
        counts[outcome] += 1
        outcomes[case.name] = outcome
        flag = '' if outcome == case.expected else \
            f'   <- expected {case.expected}'
        print(f'{outcome:15s} {case.name}{flag}', flush=True)
        if args.verbose:
            print(f'{"":15s} {message[:300]}', flush=True)
        if flag:
            wrong.append(case.name)
    print('counts: ' + ', '.join(f'{n} {k}' for k, n in counts.items()))
    return dict(counts=dict(counts), outcomes=outcomes, wrong=wrong)


def testable_mutations() -> List[str]:
    """The mutations that a case of this checkout lists.

    A case that needs the real nuScenes key frame (``../shared``) is absent
    from a checkout without it, and so is the check of its mutation.
    """
    listed = {guard for case in CASES for guard in case.guards}
    return [name for name in MUTATIONS if name in listed]


def run_mutations(names, args) -> Dict:
    """Run each mutation's cases with it made; print which notice it."""
    results, unnoticed = {}, []
    testable = testable_mutations()
    left_out = sorted(set(MUTATIONS) - set(testable))
    if left_out and not names:
        print(f'left out (their case needs the real nuScenes sample, '
              f'absent here): {left_out}', flush=True)
    for name in names or testable:
        if name not in MUTATIONS:
            raise SystemExit(f'unknown mutation {name!r}; known: '
                             f'{sorted(MUTATIONS)}')
        if name not in testable:
            raise SystemExit(f'mutation {name!r}: no case of this checkout '
                             'lists it (its case needs the real nuScenes '
                             'sample beside the checkout)')
        cases = [c for c in CASES if name in c.guards]
        seen = {c.name: run_case(c, args.timeout, name).kind for c in cases}
        noticed = [c for c in cases if seen[c.name] != c.expected]
        results[name] = seen
        verdict = 'caught' if noticed else 'UNNOTICED'
        print(f'{verdict:9s} {name}: ' + '; '.join(
            f'{c.name} -> {seen[c.name]}' for c in cases), flush=True)
        if not noticed:
            unnoticed.append(name)
    print(f'mutations: {len(results) - len(unnoticed)} of {len(results)} '
          'caught')
    return dict(mutations=results, wrong=unnoticed)


def main(argv=None) -> Dict:
    """Run the matrix (or the mutation check) and print it.

    Returns:
        dict: ``counts`` (class -> count), ``outcomes`` (case -> class)
        and ``wrong`` (cases out of their class), or for ``--mutations``
        ``mutations`` (mutation -> case -> class) and ``wrong`` (the
        mutations no case noticed).

    Raises:
        SystemExit: With status 1 if ``wrong`` is not empty.
    """
    args = parse_args(argv)
    if args.mutations is not None:
        result = run_mutations(args.mutations, args)
    else:
        result = run_matrix(args)
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(result, f, indent=1)
    if result['wrong']:
        raise SystemExit(f'{len(result["wrong"])} not as expected: '
                         f'{result["wrong"]}')
    return result


if __name__ == '__main__':
    main()
