"""Every tool imports the same way whatever the working directory.

The tools import their helpers and the plugin as installed packages
(``projects.occ_common.engine.cpu_dist`` and ``.benchmarking``), not from
``tools/`` on ``sys.path`` and without editing ``sys.path``: a tool loaded
as a module from a file (as the tests do) and a tool run from another
folder both work.
"""
import glob
import os.path as osp

import pytest

from projects.occ_common.testing.tool_logs import (REPO_ROOT, load_tool,
                                                   run_tool)

TOOLS = sorted(
    osp.relpath(p, REPO_ROOT)
    for pattern in ('tools/*.py', 'tools/*/*.py', 'demo/*.py')
    for p in glob.glob(osp.join(REPO_ROOT, pattern)))


@pytest.mark.parametrize('script', TOOLS)
def test_tool_loads_as_a_module_without_sys_path_edits(script):
    """Loading a tool script from its file succeeds (``from cpu_dist
    import ...`` needed tools/ on sys.path) and leaves sys.path alone."""
    import sys
    before = list(sys.path)
    module = load_tool(script)
    assert sys.path == before
    assert callable(getattr(module, 'main', None)), script


def test_tool_runs_from_another_folder(tmp_path):
    """``python /repo/tools/train.py --help`` from an unrelated folder (one
    tool: a start-up costs ~10 s of imports)."""
    proc = run_tool('tools/train.py', '--help', cwd=str(tmp_path),
                    timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert 'usage' in proc.stdout
