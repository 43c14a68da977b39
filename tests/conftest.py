"""Session-wide fixtures: tiny synthetic worlds shared by test files, and
one thread per pytest-xdist worker."""
import collections
import os
import shutil
import warnings

import pytest

from projects.occ_common.testing.tiny_world import make_tiny_world
from projects.occ_common.testing.tool_logs import run_create_data


def pytest_configure(config):
    """Under pytest-xdist (``make test`` runs ``-n 2``), give every worker
    and the tools it starts one thread. Two workers of two OpenMP threads
    each on two cores wait for each other at every barrier: on this
    project's 2-core CI machine torch iterations then ran 10-30x slower."""
    if os.environ.get('PYTEST_XDIST_WORKER'):
        os.environ['OMP_NUM_THREADS'] = '1'
        os.environ['MKL_NUM_THREADS'] = '1'
        import torch
        torch.set_num_threads(1)


def pytest_collection_modifyitems(session, config, items):
    """Start the modules with the most ``slow`` tests first.

    ``make test`` hands whole modules to its two workers
    (``--dist loadscope``) in collection order; a module of end-to-end runs
    met last kept one worker busy for minutes while the other idled (15.1
    minutes for the suite, ~6 of them on one worker). Longest first is the
    classic fix; the order within a module is kept.
    """
    def module(item):
        return item.nodeid.split('::')[0]

    slow = collections.Counter(
        module(item) for item in items if item.get_closest_marker('slow'))
    items.sort(key=lambda item: -slow[module(item)])


@pytest.fixture(scope='session')
def converted_tiny_world(tmp_path_factory):
    """The default tiny world (one scene of two key frames, 160x90 images)
    converted with tools/create_data.py; its one scene is both the train
    and the val split. Read-only: copy it before damaging anything."""
    root = make_tiny_world(str(tmp_path_factory.mktemp('tiny_world')))
    with warnings.catch_warnings():
        warnings.filterwarnings('ignore', 'synthetic world with one scene')
        run_create_data('--root-path', root, '--version', 'v1.0-mini')
    return root


@pytest.fixture
def world_copy(converted_tiny_world, tmp_path):
    """A private copy of :func:`converted_tiny_world` to damage."""
    copy = str(tmp_path / 'world')
    shutil.copytree(converted_tiny_world, copy)
    return copy


@pytest.fixture(params=['cpu path', 'gpu path'])
def code_path(request):
    """Run the test on the CPU's code path and again on the one GPUs take
    (:mod:`projects.occ_common.utils.device_path`), on the CPU: values
    worked out by hand must hold on both."""
    from projects.occ_common.utils.device_path import forced_accelerator_path
    with forced_accelerator_path(request.param == 'gpu path'):
        yield request.param
