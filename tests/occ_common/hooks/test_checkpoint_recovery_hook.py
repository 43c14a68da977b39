"""Repairing a work dir left behind by a killed run."""
import logging
import os
import types

from projects.occ_common.hooks import CheckpointRecoveryHook
from projects.occ_common.hooks.checkpoint_recovery_hook import (
    newest_checkpoint, repair_work_dir)


def _work_dir(tmp_path, pointer):
    """epoch_1.pth, then epoch_2.pth (newer), a partial write, a pointer."""
    for step, mtime in ((1, 1_000_000), (2, 2_000_000)):
        path = tmp_path / f'epoch_{step}.pth'
        path.write_bytes(b'ckpt')
        os.utime(path, (mtime, mtime))
    (tmp_path / 'best_occ_mIoU_epoch_1.pth').write_bytes(b'ckpt')
    (tmp_path / '.epoch_3.pth.77.deadbeef.tmp').write_bytes(b'half')
    if pointer is not None:
        (tmp_path / 'last_checkpoint').write_text(pointer)
    return tmp_path


def test_empty_pointer_is_pointed_at_the_newest_checkpoint(tmp_path):
    """'' -> epoch_2.pth (newest epoch_/iter_ file); temp file removed."""
    work = _work_dir(tmp_path, '')
    actions = repair_work_dir(str(work))
    assert (work / 'last_checkpoint').read_text() == str(
        work / 'epoch_2.pth')
    assert len(actions) == 2 and 'is empty' in actions[1]
    assert not (work / '.epoch_3.pth.77.deadbeef.tmp').exists()


def test_pointer_to_a_missing_file_is_repaired(tmp_path):
    """A pointer naming epoch_3.pth (never completed) -> epoch_2.pth."""
    work = _work_dir(tmp_path, str(tmp_path / 'epoch_3.pth'))
    repair_work_dir(str(work))
    assert (work / 'last_checkpoint').read_text().endswith('epoch_2.pth')


def test_valid_pointer_is_left_alone(tmp_path):
    """A pointer to epoch_1.pth (exists) stays, even if not the newest."""
    work = _work_dir(tmp_path, str(tmp_path / 'epoch_1.pth'))
    actions = repair_work_dir(str(work))
    assert (work / 'last_checkpoint').read_text().endswith('epoch_1.pth')
    assert actions == ['removed the partial write '
                       '.epoch_3.pth.77.deadbeef.tmp']


def test_no_checkpoint_left_removes_the_pointer(tmp_path):
    """Empty pointer and no epoch_/iter_ file: resume starts afresh."""
    (tmp_path / 'last_checkpoint').write_text('')
    assert newest_checkpoint(str(tmp_path)) is None
    repair_work_dir(str(tmp_path))
    assert os.listdir(tmp_path) == []
    assert repair_work_dir(str(tmp_path / 'missing')) == []


def test_hook_logs_what_it_did(tmp_path, caplog):
    """before_run repairs runner.work_dir and warns once per action."""
    work = _work_dir(tmp_path, '')
    logger = logging.getLogger('test_checkpoint_recovery_hook')
    runner = types.SimpleNamespace(work_dir=str(work), logger=logger)
    with caplog.at_level(logging.WARNING, logger=logger.name):
        CheckpointRecoveryHook().before_run(runner)
    assert len(caplog.records) == 2
    assert 'now names' in caplog.records[1].getMessage()
