"""The cases of ``tools/analysis_tools/fault_matrix.py``: what a case is,
how its outcome is classed, and helpers the case modules share.

A case writes a file (or a work dir) as users meet it or attackers write
it, and feeds it to one entry point of the library in a forked child.
Its load function raises :class:`DataLoss` or :class:`Silent` when it sees
that a file outside the library's remit was changed or a wrong result
accepted; anything else it raises is an error, clear when its message
names what the case expects (the file, or the rank and address).

The cases themselves: :mod:`.fault_cases_files` (checkpoints and info
files through every loader and tool), :mod:`.fault_cases_runs` (work dirs,
resumes, overrides, process groups) and :mod:`.fault_cases_inputs` (a
sample's files and the metrics' side files).
"""
import hashlib
import multiprocessing
import os
import os.path as osp
import shutil
import tempfile
from typing import Any, Callable, List, NamedTuple, Optional, Sequence

#: The outcome classes, worst first: the marker file a payload writes
#: appeared; a file outside the case's remit was changed; a wrong result
#: was accepted; the child ran past its time (or memory) budget; it died
#: of a signal; an error naming nothing the case expects; a refusal naming
#: it; a valid input loaded.
CLASSES = ('code execution', 'data loss', 'silent', 'hang', 'segfault',
           'unclear error', 'clear error', 'handled')
CLEAR, HANDLED = 'clear error', 'handled'

#: The repository root and the toy config the tool cases run.
REPO_ROOT = osp.dirname(
    osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__)))))
CONFIG = osp.join(REPO_ROOT, 'tests', 'data', 'configs', 'toy_occ.py')
#: The real nuScenes key frame (an mmdet3d v2 info file), if present.
REAL_SAMPLE = osp.join(REPO_ROOT, '..', 'shared', 'data',
                       'nuscenes_real_sample')


class DataLoss(Exception):
    """A case saw a file it does not own changed, deleted or lost."""


class Silent(Exception):
    """A case saw a wrong input or result accepted without a word."""


class Case(NamedTuple):
    """One input fed to one entry point.

    Attributes:
        name (str): What is fed to what.
        expected (str): ``'clear error'`` or ``'handled'``.
        make (callable): ``make(folder, marker)`` writes the input under
            ``folder`` (in the parent) and returns its path.
        load (callable): ``load(path)`` feeds it to the entry point (in
            the child).
        names (callable, optional): ``names(path)``: what a clear message
            must contain. Defaults to the path's base name.
        timeout (float, optional): Seconds before the case is a hang.
            Defaults to the run's ``--timeout``.
        memory_mb (float): Growth of the child's resident memory beyond
            which the case is a hang (memory exhausted). Defaults to 2048.
        guards (tuple[str]): The mutations of
            :mod:`.fault_mutations` this case must catch.
    """
    name: str
    expected: str
    make: Callable[[str, str], str]
    load: Callable[[str], Any]
    names: Optional[Callable[[str], Sequence[str]]] = None
    timeout: Optional[float] = None
    memory_mb: float = 2048
    guards: tuple = ()


def tool(script: str, *argv: str) -> Callable[[str], Any]:
    """Load function running ``main`` of a tool in the child, ``{path}``
    and ``{work}`` (a folder beside the input) in ``argv`` replaced."""

    def load(path):
        from .tool_runs import load_tool
        work = osp.join(osp.dirname(path), 'work')
        return load_tool(script).main(
            [a.format(path=path, work=work) for a in argv])

    return load


def in_child(run: Callable[[], Any]) -> None:
    """Run ``run`` in a forked child and wait (setup a case needs done in
    a fresh process, e.g. a training run)."""
    context = multiprocessing.get_context('fork')
    child = context.Process(target=_quiet, args=(run, ))
    child.start()
    child.join()
    if child.exitcode != 0:
        raise RuntimeError(f'fault matrix: setup failed ({child.exitcode})')


def _quiet(run: Callable[[], Any]) -> None:
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    run()


_TOY: List[str] = []


def toy_work_dir() -> str:
    """A work dir of the toy config after epoch 1 of 1 (``epoch_1.pth``,
    ``last_checkpoint``), trained once per process in a child; copy it
    before changing it."""
    if not _TOY:
        work = osp.join(tempfile.mkdtemp(prefix='fault_matrix_'), 'toy')

        def train():
            from .tool_runs import load_tool
            load_tool('tools/train.py').main(
                [CONFIG, '--work-dir', work, '--cfg-options',
                 'train_cfg.max_epochs=1'])

        in_child(train)
        _TOY.append(work)
    return _TOY[0]


def copy_toy_work_dir(folder: str, name: str = 'work') -> str:
    """:func:`toy_work_dir` copied to ``folder/name`` (its pointer
    rewritten to the copy); returns the copy."""
    work = shutil.copytree(toy_work_dir(), osp.join(folder, name),
                           symlinks=True)
    with open(osp.join(work, 'last_checkpoint'), 'w') as f:
        f.write(osp.join(work, 'epoch_1.pth'))
    return work


def digest(path: str) -> str:
    """SHA-1 of a file's bytes (to see whether a case changed it)."""
    with open(path, 'rb') as f:
        return hashlib.sha1(f.read()).hexdigest()


def kept(run: Callable[[str], Any],
         files: Callable[[str], Sequence[str]]) -> Callable[[str], Any]:
    """``run(path)``, then :class:`DataLoss` if any of ``files(path)``
    changed or vanished, whatever ``run`` raised."""

    def load(path):
        watched = {f: digest(f) for f in files(path)}
        try:
            return run(path)
        finally:
            for name, before in watched.items():
                if not osp.isfile(name) or digest(name) != before:
                    raise DataLoss(f'{name} was changed or removed')

    return load


__all__ = [
    'CLASSES', 'CLEAR', 'CONFIG', 'Case', 'DataLoss', 'HANDLED',
    'REAL_SAMPLE', 'REPO_ROOT', 'Silent', 'copy_toy_work_dir', 'digest',
    'in_child', 'kept', 'tool', 'toy_work_dir'
]
