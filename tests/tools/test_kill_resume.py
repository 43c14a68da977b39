"""SIGKILL tools/train.py mid-run, --resume, and end with the same weights.

The toy config trains 12 epochs of 4 iterations, a checkpoint per epoch,
no validation, in deterministic mode. A run is killed as soon as its
second checkpoint appears, resumed from whatever ``last_checkpoint``
names, and must finish with the weights of an uninterrupted run.
"""
import os
import os.path as osp
import signal
import subprocess
import sys
import time

import pytest
import torch

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')
EPOCHS = 12
ITERS_PER_EPOCH = 4  # 8 samples / batch 2
OPTIONS = [
    '--cfg-options', f'train_cfg.max_epochs={EPOCHS}',
    'train_cfg.val_interval=1000', 'randomness.seed=0',
    'randomness.deterministic=True', 'default_hooks.checkpoint.interval=1'
]


def _train_cmd(work_dir, *extra):
    return [
        sys.executable,
        osp.join(ROOT, 'tools', 'train.py'), CONFIG, '--work-dir', work_dir,
        *extra, *OPTIONS
    ]


def _state_dict(path):
    from projects.occ_common.utils import load_weights_only
    return load_weights_only(path, map_location='cpu')['state_dict']


def _resume_point(work_dir):
    """The checkpoint --resume will pick, as CheckpointRecoveryHook does."""
    from projects.occ_common.hooks.checkpoint_recovery_hook import \
        newest_checkpoint
    pointer = osp.join(work_dir, 'last_checkpoint')
    target = ''
    if osp.isfile(pointer):
        with open(pointer) as f:
            target = f.read().strip()
    if not (target and osp.isfile(target)):
        target = newest_checkpoint(work_dir)
    assert target, f'no checkpoint in {work_dir} after the kill'
    return target


@pytest.mark.slow
def test_sigkill_then_resume_matches_an_uninterrupted_run(tmp_path):
    """Kill after epoch 2's checkpoint; resume from k; weights equal.

    Resuming from epoch k restores weights, SGD momentum, the LR schedule
    and the message hub, and the sampler reshuffles epoch e with seed
    0 + e, so epochs k+1..12 repeat the uninterrupted run bit for bit.
    """
    straight = str(tmp_path / 'straight')
    proc = subprocess.run(_train_cmd(straight), cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]

    killed = str(tmp_path / 'killed')
    log = open(tmp_path / 'killed.log', 'w')
    child = subprocess.Popen(_train_cmd(killed), cwd=ROOT, stdout=log,
                             stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 240
    try:
        while not osp.exists(osp.join(killed, 'epoch_2.pth')):
            assert child.poll() is None, 'training ended before the kill'
            assert time.monotonic() < deadline, 'no checkpoint in 240 s'
            time.sleep(0.005)
        still_running = child.poll() is None
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.wait(timeout=60)
        log.close()
    assert still_running and child.returncode == -signal.SIGKILL
    assert not osp.exists(osp.join(killed, f'epoch_{EPOCHS}.pth'))

    resume_from = _resume_point(killed)
    epoch = int(osp.basename(resume_from)[len('epoch_'):-len('.pth')])
    assert 1 <= epoch < EPOCHS
    proc = subprocess.run(_train_cmd(killed, '--resume'), cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    output = proc.stdout + proc.stderr
    assert (f'resumed epoch: {epoch}, iter: {epoch * ITERS_PER_EPOCH}'
            in output)

    final = f'epoch_{EPOCHS}.pth'
    expected = _state_dict(osp.join(straight, final))
    resumed = _state_dict(osp.join(killed, final))
    assert list(resumed) == list(expected)
    for name, tensor in expected.items():
        assert torch.equal(resumed[name], tensor), name
