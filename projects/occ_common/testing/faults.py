"""A checkpoint backend that fails on purpose, for crash tests of saving.

Importing this module (a test lists it in ``custom_imports``) registers the
file backend ``faulty_local``: the ``atomic_local`` backend whose
``at_call``-th ``put`` (1-based, counted per process) fails as ``fault``
says, inside the real :func:`~projects.occ_common.engine.hooks.atomic_write`
(calls are counted per target folder, as mmengine builds a new backend
for every save):

* ``'sigkill'``: half the bytes reach the temporary file, then the process
  is killed with SIGKILL (a power cut or OOM kill mid-write);
* ``'sigint'``: half the bytes, then ``KeyboardInterrupt`` (Ctrl-C);
* ``'enospc'``: half the bytes, then ``OSError(ENOSPC)`` (a full disk);
* ``'sigkill_after'``: the file is written completely, then SIGKILL, before
  the hook writes its ``last_checkpoint`` pointer.

Select it with ``default_hooks.checkpoint.backend_args =
dict(backend='faulty_local', fault='sigkill', at_call=2)``.
"""
import collections
import errno
import io
import os
import os.path as osp
import signal
from typing import Dict
from unittest import mock

from mmengine.fileio import register_backend

from ..fileio.atomic_file_backend import AtomicLocalBackend

FAULTS = ('sigkill', 'sigint', 'enospc', 'sigkill_after')


class _HalfWriter(io.FileIO):
    """A file that writes half of what it is given, then fails."""

    fault = 'enospc'

    def write(self, data):
        super().write(bytes(data)[:len(data) // 2])
        self.flush()
        if self.fault == 'sigkill':
            os.kill(os.getpid(), signal.SIGKILL)
        if self.fault == 'sigint':
            raise KeyboardInterrupt
        raise OSError(errno.ENOSPC, 'No space left on device')


@register_backend('faulty_local')
class FaultyLocalBackend(AtomicLocalBackend):
    """``atomic_local`` with one failing ``put`` (see the module doc).

    Args:
        fault (str): One of :data:`FAULTS`.
        at_call (int): Which ``put`` fails, 1-based. Defaults to 1.
    """

    calls: Dict[str, int] = collections.defaultdict(int)

    def __init__(self, fault: str, at_call: int = 1) -> None:
        if fault not in FAULTS:
            raise ValueError(f'fault must be one of {FAULTS}, got {fault!r}')
        self.fault = fault
        self.at_call = at_call

    def put(self, obj: bytes, filepath) -> None:
        """Write atomically, failing at the chosen call."""
        folder = osp.dirname(osp.abspath(str(filepath)))
        FaultyLocalBackend.calls[folder] += 1
        if FaultyLocalBackend.calls[folder] != self.at_call:
            return super().put(obj, filepath)
        if self.fault == 'sigkill_after':
            super().put(obj, filepath)
            os.kill(os.getpid(), signal.SIGKILL)
        writer = type('Writer', (_HalfWriter, ), dict(fault=self.fault))
        with mock.patch.object(os, 'fdopen',
                               lambda fd, mode: writer(fd, 'wb')):
            return super().put(obj, filepath)
