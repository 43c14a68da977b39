"""CPUMallocTuningHook: freed activations are reused instead of faulted in
again, and the CPU runtime uses it."""
import os.path as osp
import subprocess
import sys
from types import SimpleNamespace

import pytest
from mmengine.config import Config

from projects.occ_common.engine.hooks import CPUMallocTuningHook
from projects.occ_common.testing.tool_logs import REPO_ROOT as ROOT
from projects.occ_common.utils.glibc_malloc import glibc

# Allocate, touch and free a 64 MiB tensor 10 times; print the minor page
# faults of those 10 rounds (after two warm-up rounds).
_PROBE = '''
import resource, sys, torch
if sys.argv[1] == 'hook':
    from types import SimpleNamespace
    from projects.occ_common.engine.hooks import CPUMallocTuningHook
    log = SimpleNamespace(info=print, warning=print)
    CPUMallocTuningHook().before_run(SimpleNamespace(logger=log))
def once():
    x = torch.empty(16 * 1024 * 1024)  # 64 MiB of float32
    x.fill_(1.0)
    del x
once()
once()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(10):
    once()
print('faults', resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
'''


def _faults(mode):
    proc = subprocess.run([sys.executable, '-c', _PROBE, mode], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout, int(proc.stdout.split('faults')[-1])


@pytest.mark.slow
@pytest.mark.skipif(glibc() is None, reason='needs glibc (mallopt)')
def test_freed_memory_is_reused_not_faulted_in_again():
    """64 MiB is 16,384 pages of 4 KiB. glibc's default serves it with its
    own mmap (above the 32 MiB dynamic ceiling) and unmaps it on free, so
    10 rounds fault >= 10 x 16,384 = 163,840 pages in again (fewer only
    with huge pages). With the hook the block stays in the heap: measured,
    the first round faults its 16,384 pages in and of the later ones at
    most one more (in some processes the third), so the 10 rounds after two
    warm-up rounds fault in at most one block: < 2 x 16,384."""
    _, plain = _faults('plain')
    out, tuned = _faults('hook')
    assert 'glibc malloc keeps freed memory' in out
    assert plain >= 100_000
    assert tuned < 2 * 16_384


def test_thresholds_outside_mallopt_int_are_refused():
    """mallopt takes an int: 2**31 bytes cannot be passed."""
    with pytest.raises(ValueError, match='trim_threshold'):
        CPUMallocTuningHook(trim_threshold=2**31)
    with pytest.raises(ValueError, match='mmap_threshold'):
        CPUMallocTuningHook(mmap_threshold=-1)


def test_non_glibc_logs_that_nothing_changed(monkeypatch):
    """Without glibc the hook changes nothing and says so."""
    from projects.occ_common.utils import glibc_malloc
    monkeypatch.setattr(glibc_malloc, 'glibc', lambda: None)
    messages = []
    log = SimpleNamespace(info=messages.append, warning=messages.append)
    CPUMallocTuningHook().before_run(SimpleNamespace(logger=log))
    assert messages == [
        'CPUMallocTuningHook: the C library is not glibc or refused the '
        'thresholds; the allocator is unchanged'
    ]


def test_cpu_runtime_uses_it_and_keeps_default_hooks():
    """The CPU runtime adds the hook after default_runtime's custom hooks
    (none of which is lost); the paper runtime does not have it."""
    cpu = Config.fromfile(
        osp.join(ROOT, 'configs', '_base_', 'cpu_smoke_runtime.py'))
    paper = Config.fromfile(
        osp.join(ROOT, 'configs', '_base_', 'default_runtime.py'))
    assert cpu.custom_hooks[:-1] == paper.custom_hooks
    assert cpu.custom_hooks[-1] == dict(type='CPUMallocTuningHook')
    assert all(h['type'] != 'CPUMallocTuningHook'
               for h in paper.custom_hooks)
