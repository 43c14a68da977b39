"""--resume finds the newest complete checkpoint, whatever a crash left."""
import logging
import os
import types

import pytest
import torch
from mmengine.config import Config

from projects.occ_common.hooks import CheckpointRecoveryHook
from projects.occ_common.hooks.checkpoint_recovery_hook import (
    checkpoint_problem, newest_checkpoint, repair_work_dir)

DEAD_PID = 2**22 + 1  # above Linux's pid_max: never a running process


def _save(path, step, mtime):
    torch.save({'meta': {'epoch': step}, 'state_dict': {}}, path)
    os.utime(path, (mtime, mtime))


def _work_dir(tmp_path, pointer=None, truncate_newest=False):
    """epoch_1.pth, epoch_2.pth (newer), a best file, a dead partial
    write, a live one (ours), and optionally a pointer."""
    for step, mtime in ((1, 1_000_000), (2, 2_000_000)):
        _save(tmp_path / f'epoch_{step}.pth', step, mtime)
    if truncate_newest:
        data = (tmp_path / 'epoch_2.pth').read_bytes()
        (tmp_path / 'epoch_2.pth').write_bytes(data[:len(data) // 2])
        os.utime(tmp_path / 'epoch_2.pth', (2_000_000, 2_000_000))
    (tmp_path / 'best_occ_mIoU_epoch_1.pth').write_bytes(b'x')
    (tmp_path / f'.epoch_3.pth.{DEAD_PID}.deadbeef.tmp').write_bytes(b'h')
    (tmp_path / f'.epoch_9.pth.{os.getppid()}.0badf00d.tmp').write_bytes(
        b'h')
    if pointer is not None:
        (tmp_path / 'last_checkpoint').write_text(pointer)
    return tmp_path


@pytest.mark.parametrize('pointer', [None, '', 'epoch_1.pth', 'gone.pth'])
def test_pointer_names_the_newest_complete_checkpoint(tmp_path, pointer):
    """Missing, empty, older or dangling pointer: -> epoch_2.pth.

    A kill between the first epoch_N.pth and the first pointer (None),
    during the pointer's write (''), after a verified save but before the
    pointer moved ('epoch_1.pth'), or a deleted target ('gone.pth').
    Only the partial write of the dead writer is removed; the live one
    (the parent process's pid) is kept.
    """
    if pointer:
        pointer = str(tmp_path / pointer)
    work = _work_dir(tmp_path, pointer)
    actions = repair_work_dir(str(work))
    assert (work / 'last_checkpoint').read_text() == str(
        work / 'epoch_2.pth')
    assert actions[0] == ('removed the partial write '
                          f'.epoch_3.pth.{DEAD_PID}.deadbeef.tmp')
    assert 'now names the newest complete checkpoint' in actions[1]
    assert not (work / f'.epoch_3.pth.{DEAD_PID}.deadbeef.tmp').exists()
    assert (work / f'.epoch_9.pth.{os.getppid()}.0badf00d.tmp').exists()


def test_truncated_newest_is_skipped(tmp_path):
    """epoch_2.pth cut in half (a non-atomic writer): resume epoch_1."""
    work = _work_dir(tmp_path, str(tmp_path / 'epoch_2.pth'),
                     truncate_newest=True)
    assert 'truncated' in checkpoint_problem(str(work / 'epoch_2.pth'))
    actions = repair_work_dir(str(work))
    assert (work / 'last_checkpoint').read_text().endswith('epoch_1.pth')
    assert any(a.startswith(f'skipped {work}/epoch_2.pth') for a in actions)
    assert newest_checkpoint(str(work)) == str(work / 'epoch_1.pth')


def test_valid_newest_pointer_is_left_alone(tmp_path):
    work = _work_dir(tmp_path, str(tmp_path / 'epoch_2.pth'))
    actions = repair_work_dir(str(work))
    assert actions == ['removed the partial write '
                       f'.epoch_3.pth.{DEAD_PID}.deadbeef.tmp']


def test_only_broken_checkpoints_refuse_to_restart(tmp_path):
    """Checkpoints exist but none loads: an error, not a silent restart."""
    (tmp_path / 'epoch_1.pth').write_bytes(b'')
    (tmp_path / 'last_checkpoint').write_text(str(tmp_path / 'epoch_1.pth'))
    with pytest.raises(RuntimeError,
                       match='no checkpoint in .* is complete .*epoch_1.pth'
                       '.*is empty'):
        repair_work_dir(str(tmp_path))


def test_no_checkpoint_left_removes_the_pointer(tmp_path):
    """Empty pointer and no epoch_/iter_ file: resume starts afresh."""
    (tmp_path / 'last_checkpoint').write_text('')
    assert newest_checkpoint(str(tmp_path)) is None
    actions = repair_work_dir(str(tmp_path))
    assert os.listdir(tmp_path) == []
    assert 'training starts from scratch' in actions[-1]
    assert repair_work_dir(str(tmp_path / 'missing')) == []


def _runner(work, **cfg):
    logger = logging.getLogger('test_checkpoint_recovery_hook')
    return types.SimpleNamespace(
        work_dir=str(work), logger=logger, cfg=Config(cfg))


def test_hook_acts_only_on_auto_resume(tmp_path, caplog):
    """resume=True without load_from repairs; test runs touch nothing."""
    work = _work_dir(tmp_path, '')
    for cfg in (dict(), dict(resume=True, load_from='x.pth')):
        CheckpointRecoveryHook().before_run(_runner(work, **cfg))
        assert (work / 'last_checkpoint').read_text() == ''
    runner = _runner(work, resume=True, load_from=None)
    with caplog.at_level(logging.WARNING, logger=runner.logger.name):
        CheckpointRecoveryHook().before_run(runner)
    assert len(caplog.records) == 2
    assert 'now names' in caplog.records[1].getMessage()
