"""--resume finds the complete checkpoint of the latest step, whatever a
crash or a copy left, and never goes back in time."""
import logging
import os
import types

import pytest
import torch
from mmengine.config import Config

from projects.occ_common.engine.hooks import CheckpointRecoveryHook
from projects.occ_common.engine.hooks.checkpoint_recovery_hook import (
    checkpoint_problem, newest_checkpoint, repair_work_dir)

DEAD_PID = 2**22 + 1  # above Linux's pid_max: never a running process


def _save(path, step, mtime):
    torch.save({'meta': {'epoch': step, 'iter': 4 * step}, 'state_dict': {}},
               path)
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
    assert ('now names the complete checkpoint of the latest step'
            in actions[1])
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


def _copied_work_dir(tmp_path, pointer):
    """epoch_1..3.pth as ``cp`` leaves them when it copies epoch_1.pth
    last: the earlier the step, the newer the file time."""
    work = tmp_path / 'copy'
    work.mkdir()
    for step in (1, 2, 3):
        _save(work / f'epoch_{step}.pth', step, 4_000_000 - step * 1_000_000)
    if pointer is not None:
        (work / 'last_checkpoint').write_text(pointer.format(work=work))
    return work


@pytest.mark.parametrize('pointer', [
    '{work}/epoch_3.pth', None, '/gone/original_work_dir/epoch_3.pth',
    '{work}/epoch_1.pth'
])
def test_copied_work_dir_resumes_from_the_latest_step(tmp_path, pointer):
    """File times reversed by a copy: --resume still picks epoch_3.pth.

    A valid pointer to it is left alone (before, the file times won:
    the pointer was moved to epoch_1.pth, and the run went on to
    overwrite epoch_2.pth and epoch_3.pth); a missing pointer, one naming
    the original work dir (gone), or one left behind on epoch_1.pth
    (killed before it moved) now names epoch_3.pth.
    """
    work = _copied_work_dir(tmp_path, pointer)
    actions = repair_work_dir(str(work))
    assert (work / 'last_checkpoint').read_text() == str(
        work / 'epoch_3.pth')
    if pointer == '{work}/epoch_3.pth':
        assert actions == []
    else:
        assert 'of the latest step' in actions[0]


def test_pointer_wins_a_tie_of_steps(tmp_path):
    """The pointer names the original work dir's epoch_3.pth, which still
    exists: same step as the copy's, so the pointer is trusted."""
    original = _copied_work_dir(tmp_path, None)
    copy = tmp_path / 'copy2'
    copy.mkdir()
    _save(copy / 'epoch_3.pth', 3, 9_000_000)
    (copy / 'last_checkpoint').write_text(str(original / 'epoch_3.pth'))
    assert repair_work_dir(str(copy)) == []


def test_steps_from_meta_when_names_do_not_compare(tmp_path):
    """epoch_2.pth (iteration 8) is later than iter_6.pth, and a pointer
    to other.pth (iteration 12) later than both, whatever the times."""
    _save(tmp_path / 'epoch_2.pth', 2, 1_000_000)
    torch.save({'meta': {'epoch': 1, 'iter': 6}, 'state_dict': {}},
               tmp_path / 'iter_6.pth')
    assert newest_checkpoint(str(tmp_path)) == str(tmp_path / 'epoch_2.pth')
    _save(tmp_path / 'other.pth', 3, 0)
    other = str(tmp_path / 'other.pth')
    assert newest_checkpoint(str(tmp_path), other) == other


def test_resume_path_refuses_to_overwrite_later_steps(tmp_path):
    """--resume epoch_1.pth with epoch_2.pth and epoch_3.pth in the work
    dir: refused, naming them; from epoch_3.pth it goes ahead."""
    work = _copied_work_dir(tmp_path, None)
    (work / 'epoch_2.pth').write_bytes(b'truncated')  # not overwritten data
    runner = _runner(work, resume=True, load_from=str(work / 'epoch_1.pth'))
    with pytest.raises(RuntimeError) as err:
        CheckpointRecoveryHook().before_run(runner)
    message = str(err.value)
    assert f'--resume {work}/epoch_1.pth' in message
    assert f'{work}/epoch_3.pth' in message
    assert 'epoch_2.pth' not in message
    CheckpointRecoveryHook().before_run(
        _runner(work, resume=True, load_from=str(work / 'epoch_3.pth')))
