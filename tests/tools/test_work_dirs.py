"""A training run owns its work dir and never eats another run's files.

Before: a work dir named ``exp[1]`` (a glob pattern) made ``--resume``
find no checkpoint and train from scratch over them; two runs into one
work dir both exited 0 with the first one's checkpoints gone; re-running
a finished run's command without ``--resume`` overwrote its
checkpoints; a ``last_checkpoint`` that is a symlink had its target
overwritten. tools/train.py runs in this process on the toy config
(~2 s an epoch).
"""
import hashlib
import os
import os.path as osp
import socket
import subprocess
import sys
import time

import pytest
import torch

from projects.occ_common.engine.hooks.checkpoint_recovery_hook import (
    check_no_later_checkpoint, repair_work_dir)
from projects.occ_common.engine.run_lock import (LOCK_NAME, STALE_SECONDS,
                                                 RunLock, _start_time,
                                                 owner_gone)
from projects.occ_common.fileio import load_checkpoint_file
from projects.occ_common.testing.tool_logs import REPO_ROOT, load_tool

CONFIG = osp.join(REPO_ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


def _train(work_dir, *argv):
    return load_tool('tools/train.py').main(
        [CONFIG, '--work-dir', str(work_dir), *argv])


def _digest(path):
    with open(path, 'rb') as f:
        return hashlib.sha1(f.read()).hexdigest()


def _steps(folder):
    for step in (1, 2, 3):
        torch.save(dict(meta=dict(epoch=step, iter=step), state_dict={}),
                   osp.join(folder, f'epoch_{step}.pth'))


# -- glob characters in the work dir ----------------------------------------


def test_bracketed_work_dir_resumes_from_its_latest_checkpoint(tmp_path):
    """``exp[1]`` holds epoch_1..3.pth and no pointer: --resume points at
    epoch_3.pth (glob read ``exp[1]`` as ``exp1`` and found nothing:
    "training starts from scratch"), and --resume epoch_1.pth is refused
    because epoch_2/3.pth would be overwritten."""
    work = tmp_path / 'exp[1]'
    work.mkdir()
    _steps(str(work))
    actions = repair_work_dir(str(work))
    with open(work / 'last_checkpoint') as f:
        assert f.read() == str(work / 'epoch_3.pth')
    assert not any('from scratch' in line for line in actions)
    with pytest.raises(RuntimeError, match=r'exp\[1\]/epoch_2\.pth, .*'
                       r'exp\[1\]/epoch_3\.pth\), which the resumed run'):
        check_no_later_checkpoint(str(work), str(work / 'epoch_1.pth'))


# -- the lock --------------------------------------------------------------


@pytest.fixture
def other_process():
    """A live process that is not this one (its pid and start time)."""
    proc = subprocess.Popen([sys.executable, '-c',
                             'import time; time.sleep(60)'])
    yield proc
    proc.kill()
    proc.wait()


def _write_lock(work, **owner):
    import json
    work.mkdir(exist_ok=True)
    (work / LOCK_NAME).write_text(json.dumps(owner))


def test_second_run_into_a_work_dir_in_use_refuses_in_one_line(
        tmp_path, other_process, capsys):
    """A live run of this host holds the lock: the second run ends with one
    line naming it, having written nothing (no log folder, no config
    copy, no checkpoint)."""
    work = tmp_path / 'work'
    pid = other_process.pid
    _write_lock(work, host=socket.gethostname(), pid=pid,
                start=_start_time(pid), token='t', started='then',
                command='tools/train.py first')
    with pytest.raises(SystemExit) as exit_:
        _train(work, '--cfg-options', 'train_cfg.max_epochs=1')
    message = str(exit_.value.code)
    assert f'work dir {work} is in use by another run (pid {pid} on host ' \
        f'{socket.gethostname()}, since then: tools/train.py first)' in \
        message and '\n' not in message
    assert sorted(os.listdir(work)) == [LOCK_NAME]


def test_lock_of_a_killed_run_is_taken_over(tmp_path):
    """A SIGKILLed run cannot release its lock: its pid no longer runs on
    this host, so the next run takes the lock over, trains, and releases
    it at its end."""
    proc = subprocess.Popen([sys.executable, '-c', 'pass'])
    proc.wait()
    work = tmp_path / 'work'
    _write_lock(work, host=socket.gethostname(), pid=proc.pid, token='t')
    _train(work, '--cfg-options', 'train_cfg.max_epochs=1')
    assert osp.isfile(work / 'epoch_1.pth')
    assert not osp.exists(work / LOCK_NAME)


def test_stale_and_live_owners(tmp_path, other_process):
    """The rule of ``owner_gone``, case by case: another host's lock is
    stale after STALE_SECONDS without a heartbeat (300 s), this host's
    when its pid is gone or belongs to a process started at another
    time (a reused pid), or it is this process's own."""
    here, now = socket.gethostname(), time.time()
    pid = other_process.pid
    live = dict(host=here, pid=pid, start=_start_time(pid))
    assert owner_gone(live, now) is None
    assert 'pid reused' in owner_gone(dict(live, start='1'), now)
    assert 'this process' in owner_gone(dict(live, pid=os.getpid()), now)
    assert owner_gone(dict(host='elsewhere', pid=1), now - 10, now) is None
    assert 'has not touched it for 301 s' in owner_gone(
        dict(host='elsewhere', pid=1), now - STALE_SECONDS - 1, now)
    lock = RunLock(str(tmp_path / 'w'))
    assert lock.acquire() is None
    assert RunLock(str(tmp_path / 'w')).acquire().startswith(
        f'took over {lock.path} of a run that did not release it (it is '
        "this process's own")
    with pytest.raises(Exception, match='this run lost its lock'):
        lock.check_held()


# -- an earlier run's checkpoints -----------------------------------------


def test_rerun_without_resume_keeps_the_finished_run(tmp_path):
    """The same command again (no --resume) refuses, naming the files;
    epoch_1.pth is untouched. With --resume it trains on."""
    work = tmp_path / 'work'
    _train(work, '--cfg-options', 'train_cfg.max_epochs=1')
    before = _digest(work / 'epoch_1.pth')
    with pytest.raises(SystemExit, match=r'holds the checkpoints of an '
                       r'earlier run \(epoch_1\.pth, last_checkpoint\), '
                       'which this run would overwrite: pass --resume'):
        _train(work, '--cfg-options', 'train_cfg.max_epochs=1')
    assert _digest(work / 'epoch_1.pth') == before
    _train(work, '--resume', '--cfg-options', 'train_cfg.max_epochs=2')
    assert load_checkpoint_file(str(work / 'epoch_2.pth'))['meta'][
        'iter'] == 8


def test_symlinked_pointer_target_is_not_written(tmp_path):
    """``last_checkpoint`` is a symlink to a file of the user's that names
    epoch_1.pth: the resumed run replaces the link by a file naming
    epoch_2.pth and leaves the user's file as it was (mmengine wrote the
    new path into it through the link)."""
    work = tmp_path / 'work'
    _train(work, '--cfg-options', 'train_cfg.max_epochs=1')
    mine = tmp_path / 'my_latest.txt'
    mine.write_text(str(work / 'epoch_1.pth'))
    os.remove(work / 'last_checkpoint')
    os.symlink(mine, work / 'last_checkpoint')
    _train(work, '--resume', '--cfg-options', 'train_cfg.max_epochs=2')
    assert mine.read_text() == str(work / 'epoch_1.pth')
    assert not osp.islink(work / 'last_checkpoint')
    with open(work / 'last_checkpoint') as f:
        assert f.read() == str(work / 'epoch_2.pth')


@pytest.mark.slow
def test_two_concurrent_runs_the_second_refuses(tmp_path):
    """A real first run (a child process) and a second one started while
    it trains: the second refuses; the first ends with exit 0 and all its
    checkpoints (before: both exited 0, and the first run's checkpoints
    were the second's). The first run pauses before its 5th iteration
    (epoch 2 of 2; epoch_1.pth written) until the test has tried the
    second run, so it is mid-training however loaded the machine: with a
    race instead (100 epochs), a loaded CI machine finished the first run
    before the second started, which then met finished checkpoints."""
    work = tmp_path / 'work'
    resume_file = tmp_path / 'second_run_tried'
    first = subprocess.Popen(
        [sys.executable, osp.join(REPO_ROOT, 'tools', 'train.py'), CONFIG,
         '--work-dir', str(work), '--cfg-options', 'train_cfg.max_epochs=2',
         'train_cfg.val_interval=2', 'model.pause_at_iter=5',
         f'model.resume_file={resume_file}'],
        cwd=REPO_ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        text=True, env=dict(os.environ, CUDA_VISIBLE_DEVICES=''))
    try:
        deadline = time.time() + 300
        while not osp.exists(work / 'epoch_1.pth'):
            assert first.poll() is None, first.stderr.read()[-3000:]
            assert time.time() < deadline, 'no epoch_1.pth within 300 s'
            time.sleep(0.2)
        with pytest.raises(SystemExit, match=f'work dir {work} is in use by '
                           f'another run \\(pid {first.pid}'):
            _train(work, '--cfg-options', 'train_cfg.max_epochs=1')
    finally:
        resume_file.touch()
    assert first.wait(timeout=300) == 0, first.stderr.read()[-3000:]
    meta = load_checkpoint_file(str(work / 'epoch_2.pth'))['meta']
    assert (meta['epoch'], meta['iter']) == (2, 8)
