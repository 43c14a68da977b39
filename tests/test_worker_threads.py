"""``make test`` runs two pytest-xdist workers on a 2-core machine; the
conftest gives each of them, and every tool they start, one thread."""
import os
import subprocess
import sys

import torch


def _conftest(config):
    """The tests/conftest.py plugin module."""
    for plugin in config.pluginmanager.get_plugins():
        path = getattr(plugin, '__file__', '') or ''
        if path.endswith(os.path.join('tests', 'conftest.py')):
            return plugin
    raise AssertionError('tests/conftest.py is not loaded')


def test_a_worker_and_the_tools_it_starts_run_one_thread(
        request, monkeypatch):
    """As worker ``gw1``: torch here has 1 thread after the hook, and a
    child python (how tests run tools/train.py) starts with 1 too, not
    with one per core."""
    threads = torch.get_num_threads()
    for name in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
        monkeypatch.delenv(name, raising=False)  # restored afterwards
    monkeypatch.setenv('PYTEST_XDIST_WORKER', 'gw1')
    try:
        _conftest(request.config).pytest_configure(request.config)
        assert torch.get_num_threads() == 1
        child = subprocess.run(
            [sys.executable, '-c',
             'import torch; print(torch.get_num_threads())'],
            capture_output=True, text=True, check=True)
        assert child.stdout.strip() == '1'
    finally:
        torch.set_num_threads(threads)


def test_outside_xdist_the_hook_changes_nothing(request, monkeypatch):
    """Run in-process (``TEST_WORKERS=0``), the thread count stays."""
    threads = torch.get_num_threads()
    monkeypatch.delenv('PYTEST_XDIST_WORKER', raising=False)
    monkeypatch.setenv('OMP_NUM_THREADS', '7')
    _conftest(request.config).pytest_configure(request.config)
    assert torch.get_num_threads() == threads
    assert os.environ['OMP_NUM_THREADS'] == '7'
