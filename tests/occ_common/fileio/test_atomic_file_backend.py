"""Atomic writes: the old file survives a crash mid-write."""
import io
import os

import pytest
import torch
from mmengine.fileio import get_file_backend
from mmengine.runner.checkpoint import save_checkpoint

from projects.occ_common.fileio import (AtomicLocalBackend, atomic_write,
                                        register_atomic_backend)
from projects.occ_common.fileio.atomic_file_backend import is_temporary_file

BACKEND_ARGS = dict(backend='atomic_local')


class _HalfWriter(io.FileIO):
    """A file that writes half of what it is given, then fails."""

    def write(self, data):
        super().write(bytes(data)[:len(data) // 2])
        raise OSError(28, 'No space left on device')


def _fail_halfway(monkeypatch):
    """Make atomic_write's temporary file a :class:`_HalfWriter`.

    atomic_write opens its temporary file through ``os.fdopen``;
    monkeypatch restores it after the test.
    """
    monkeypatch.setattr(os, 'fdopen',
                        lambda fd, mode: _HalfWriter(fd, 'wb'))


def test_put_and_put_text_replace_the_file(tmp_path):
    """Content, a created folder and no leftovers; mode follows umask."""
    backend = AtomicLocalBackend()
    path = tmp_path / 'sub' / 'a.bin'
    backend.put(b'first', path)
    backend.put(b'second', path)
    assert path.read_bytes() == b'second'
    backend.put_text('h\u00e9', tmp_path / 'b.txt')
    assert (tmp_path / 'b.txt').read_bytes() == 'h\u00e9'.encode()
    assert sorted(os.listdir(tmp_path / 'sub')) == ['a.bin']
    umask = os.umask(0)
    os.umask(umask)
    assert os.stat(path).st_mode & 0o777 == 0o666 & ~umask


def test_failure_mid_write_keeps_the_old_file(tmp_path, monkeypatch):
    """After a write error halfway: old bytes intact, no temporary file."""
    path = tmp_path / 'epoch_1.pth'
    atomic_write(path, b'old checkpoint')
    _fail_halfway(monkeypatch)
    with pytest.raises(OSError, match='No space left'):
        atomic_write(path, b'x' * 1000)
    assert path.read_bytes() == b'old checkpoint'
    assert os.listdir(tmp_path) == ['epoch_1.pth']


def test_empty_payload_and_temporary_names(tmp_path):
    """b'' writes an empty file; temp names are recognised, others not."""
    atomic_write(tmp_path / 'empty', b'')
    assert (tmp_path / 'empty').read_bytes() == b''
    assert is_temporary_file('.epoch_3.pth.1234.0a1b2c3d.tmp')
    assert not is_temporary_file('epoch_3.pth')
    assert not is_temporary_file('.hidden.tmp')


def test_mmengine_save_checkpoint_goes_through_the_backend(
        tmp_path, monkeypatch):
    """backend_args reach the .pth write of mmengine's save_checkpoint.

    mmengine 0.10.7: CheckpointHook -> Runner.save_checkpoint ->
    mmengine.runner.checkpoint.save_checkpoint(..., backend_args) ->
    get_file_backend(filename, backend_args).put. A failing write there
    must leave the previous checkpoint loadable. The backend is registered
    explicitly (SafeCheckpointHook does it), never on import.
    """
    register_atomic_backend()
    register_atomic_backend()  # idempotent
    assert isinstance(
        get_file_backend(str(tmp_path), backend_args=BACKEND_ARGS),
        AtomicLocalBackend)
    path = str(tmp_path / 'epoch_1.pth')
    save_checkpoint({'w': torch.ones(3)}, path, backend_args=BACKEND_ARGS)
    _fail_halfway(monkeypatch)
    with pytest.raises(OSError):
        save_checkpoint({'w': torch.zeros(300)}, path,
                        backend_args=BACKEND_ARGS)
    loaded = torch.load(path, weights_only=True)
    assert torch.equal(loaded['w'], torch.ones(3))
    assert os.listdir(tmp_path) == ['epoch_1.pth']
