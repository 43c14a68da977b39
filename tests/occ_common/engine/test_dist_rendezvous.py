"""A rank whose peers never arrive fails within the stated deadline,
naming itself and the address (before: it waited the process group's
30 minutes without a word)."""
import os
import subprocess
import sys
import time

import pytest

from projects.occ_common.analysis.ddp_check import free_port
from projects.occ_common.engine import dist_rendezvous
from projects.occ_common.engine.dist_rendezvous import (DEFAULT_INIT_TIMEOUT,
                                                        INIT_TIMEOUT_ENV,
                                                        init_timeout)
from projects.occ_common.testing.tool_logs import REPO_ROOT

DIST_RENDEZVOUS = dist_rendezvous.__file__

#: What tools/train.py and tools/test.py do first under --launcher pytorch.
_TOOLS = """
from mmengine.config import Config
from projects.occ_common.engine.cpu_dist import setup_distributed
setup_distributed(Config(dict(launcher='pytorch',
                              env_cfg=dict(dist_cfg=dict(backend='nccl')))))
print('formed')
"""
#: The deadline around torch's own rendezvous; the module is loaded by
#: its path, without the plugins the package registers (~9 s less).
_BARE = f"""
import importlib.util
import torch.distributed as dist
spec = importlib.util.spec_from_file_location(
    'dist_rendezvous', {DIST_RENDEZVOUS!r})
module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(module)
with module.rendezvous_deadline():
    dist.init_process_group('gloo')
print('formed')
"""


@pytest.mark.parametrize('script', [
    pytest.param(_BARE, id='deadline'),
    pytest.param(_TOOLS, id='tools', marks=pytest.mark.slow),
])
def test_rank_zero_of_two_alone_fails_naming_rank_and_address(script):
    """Rank 0 of a world of 2 under torchrun's variables, and no rank 1:
    with OCC_DIST_INIT_TIMEOUT=2 it exits 1 after about 2 s with one
    line; a 60 s timeout bounds the test where it would wait."""
    port = free_port()
    env = dict(os.environ, RANK='0', LOCAL_RANK='0', WORLD_SIZE='2',
               MASTER_ADDR='127.0.0.1', MASTER_PORT=str(port),
               CUDA_VISIBLE_DEVICES='', PYTHONPATH=REPO_ROOT,
               **{INIT_TIMEOUT_ENV: '2'})
    start = time.time()
    proc = subprocess.run([sys.executable, '-c', script], env=env,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1 and 'formed' not in proc.stdout
    assert (f'error: rank 0 of 2: the process group at 127.0.0.1:{port} '
            'did not form within 2 s: a peer is missing') in proc.stderr
    assert time.time() - start < 30


def test_the_deadline_is_stated_and_checked(monkeypatch):
    monkeypatch.delenv(INIT_TIMEOUT_ENV, raising=False)
    assert init_timeout() == DEFAULT_INIT_TIMEOUT == 600
    monkeypatch.setenv(INIT_TIMEOUT_ENV, '0')
    assert init_timeout() == 0
    for bad in ('soon', '-1'):
        monkeypatch.setenv(INIT_TIMEOUT_ENV, bad)
        with pytest.raises(ValueError, match=f'{INIT_TIMEOUT_ENV}='):
            init_timeout()


def test_a_failed_rendezvous_names_rank_and_address(monkeypatch):
    """torch's own failure inside the block (here the DistNetworkError of
    a rendezvous port another process holds) is raised naming the rank,
    the world size and the address, with torch's message after it (before:
    torch's message alone, naming neither)."""
    import socket

    import torch.distributed as dist
    holder = socket.socket()
    holder.bind(('127.0.0.1', 0))
    holder.listen(1)
    port = holder.getsockname()[1]
    monkeypatch.setenv('RANK', '0')
    monkeypatch.setenv('WORLD_SIZE', '2')
    monkeypatch.setenv('MASTER_ADDR', '127.0.0.1')
    monkeypatch.setenv('MASTER_PORT', str(port))
    try:
        with pytest.raises(RuntimeError) as err:
            with dist_rendezvous.rendezvous_deadline(30):
                dist.init_process_group('gloo')
    finally:
        holder.close()
    assert str(err.value).startswith(
        f'rank 0 of 2: could not form the process group at '
        f'127.0.0.1:{port}: ')
    assert not dist.is_initialized()
