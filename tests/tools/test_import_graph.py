"""The library's floors hold: no import cycle, no import running up a
floor, no library module, tool or demo importing a test helper
(tools/analysis_tools/import_graph.py)."""
import os

from projects.occ_common.testing.tool_logs import REPO_ROOT, load_tool

graph = load_tool('tools/analysis_tools/import_graph.py')


def _write(root, path, text=''):
    full = os.path.join(root, path)
    os.makedirs(os.path.dirname(full), exist_ok=True)
    with open(full, 'w') as f:
        f.write(text)


def test_the_repository_has_no_cycle_upward_import_or_test_helper_import():
    """The house as it is: 0 cycles, 0 upward imports, 0 imports of
    ``projects.occ_common.testing`` from outside it."""
    assert graph.analyse(REPO_ROOT) == ([], [], [])
    assert graph.main(['--root', REPO_ROOT]) == 0


def test_each_kind_of_finding_is_found(tmp_path):
    """A tree with one of each: ``fileio.a`` and ``fileio.b`` import each
    other (a cycle), ``utils.c`` (floor 0) imports ``fileio.a`` (floor 1)
    through a relative import, and ``deployment.d`` and ``tools/t.py``
    import ``testing.h``; the projects' ``__init__`` imports everything
    and is not upward (it sits above the floors)."""
    root = str(tmp_path)
    common = 'projects/occ_common/'
    _write(root, common + '__init__.py', 'from . import fileio, utils\n')
    _write(root, common + 'fileio/__init__.py')
    _write(root, common + 'fileio/a.py', 'from . import b\n')
    _write(root, common + 'fileio/b.py', 'from .a import x\n')
    _write(root, common + 'utils/__init__.py')
    _write(root, common + 'utils/c.py', 'def f():\n'
           '    from ..fileio import a\n')
    _write(root, common + 'deployment/__init__.py')
    _write(root, common + 'deployment/d.py',
           'from projects.occ_common.testing.h import y\n')
    _write(root, common + 'testing/__init__.py')
    _write(root, common + 'testing/h.py', 'from ..fileio import a\n')
    _write(root, 'tools/t.py', 'import projects.occ_common.testing.h\n')
    cycles, upward, testing = graph.analyse(root)
    assert cycles == [['projects.occ_common.fileio.a',
                       'projects.occ_common.fileio.b']]
    assert upward == [
        'projects.occ_common.deployment.d -> '
        'projects.occ_common.testing.h (floor 12 -> 13)',
        'projects.occ_common.utils.c -> projects.occ_common.fileio.a '
        '(floor 0 -> 1)'
    ]
    assert testing == [
        'projects.occ_common.deployment.d -> projects.occ_common.testing.h',
        'tools/t.py -> projects.occ_common.testing.h'
    ]
    assert graph.main(['--root', root]) == 1
