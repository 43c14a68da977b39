"""A local file backend whose writes are atomic: all or nothing on disk.

mmengine's ``LocalBackend.put`` opens the target with ``'wb'``, which
truncates it first: a crash or SIGKILL while a checkpoint is written leaves
a truncated ``epoch_N.pth`` that ``--resume`` then fails to load. This
backend writes to a temporary file in the same folder, flushes and
``fsync``\\ s it, and ``os.replace``\\ s it over the target (atomic on POSIX
and Windows within one file system), so the target is always either the
old file or the complete new one. A crash leaves at most a temporary file
(:func:`is_temporary_file`), which
:class:`~.checkpoint_recovery_hook.CheckpointRecoveryHook` removes.

:class:`~.safe_checkpoint_hook.SafeCheckpointHook` writes through it (it
registers the backend as ``atomic_local`` with mmengine when it is built;
nothing is registered on import): mmengine 0.10.7's ``CheckpointHook`` hands
``backend_args`` to ``Runner.save_checkpoint``, which writes the ``.pth``
through ``get_file_backend(...).put``.
"""
import os
import os.path as osp
import re
import secrets
from pathlib import Path
from typing import Union

from mmengine.fileio import LocalBackend, register_backend
from mmengine.fileio.backends.registry_utils import backends

#: Name under which the backend is registered with mmengine.
BACKEND_NAME = 'atomic_local'

# '.{target name}.{pid}.{8 hex}.tmp': hidden, and unique per writer.
_TEMP_PATTERN = re.compile(r'^\..+\.\d+\.[0-9a-f]{8}\.tmp$')


def temporary_path(filepath: str) -> str:
    """A fresh temporary name next to ``filepath``."""
    folder, name = osp.split(osp.abspath(filepath))
    return osp.join(folder,
                    f'.{name}.{os.getpid()}.{secrets.token_hex(4)}.tmp')


def is_temporary_file(name: str) -> bool:
    """Whether ``name`` (a base name) is a temporary file of this backend."""
    return bool(_TEMP_PATTERN.match(name))


def _fsync_folder(folder: str) -> None:
    """Make the rename durable: fsync the folder entry where supported."""
    if not hasattr(os, 'O_DIRECTORY'):
        return  # Windows: renames are journaled by the file system.
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write(filepath: Union[str, Path], data: bytes) -> None:
    """Replace ``filepath`` with ``data`` in one step.

    Args:
        filepath (str | Path): Target file; its folder is created.
        data (bytes): The new content.

    Raises:
        OSError: If writing fails; the target is left as it was and the
            temporary file is removed.
    """
    filepath = osp.abspath(str(filepath))
    folder = osp.dirname(filepath)
    os.makedirs(folder, exist_ok=True)
    temp = temporary_path(filepath)
    # 0o666 through os.open lets the umask set the mode, as open() would.
    fd = os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, 'wb') as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(temp, filepath)
    except BaseException:
        # KeyboardInterrupt included: never leave the temporary file.
        if osp.exists(temp):
            os.remove(temp)
        raise
    _fsync_folder(folder)


class AtomicLocalBackend(LocalBackend):
    """``LocalBackend`` whose ``put`` / ``put_text`` are atomic.

    Reading, listing and removing are ``LocalBackend``'s.
    """

    def put(self, obj: bytes, filepath: Union[str, Path]) -> None:
        """Write bytes atomically (see :func:`atomic_write`).

        Args:
            obj (bytes): Data to write.
            filepath (str | Path): Target file.
        """
        atomic_write(filepath, obj)

    def put_text(self,
                 obj: str,
                 filepath: Union[str, Path],
                 encoding: str = 'utf-8') -> None:
        """Write text atomically (see :func:`atomic_write`).

        Args:
            obj (str): Text to write.
            filepath (str | Path): Target file.
            encoding (str): Text encoding. Defaults to 'utf-8'.
        """
        atomic_write(filepath, obj.encode(encoding))


def register_atomic_backend() -> None:
    """Register :class:`AtomicLocalBackend` as ``atomic_local`` (once)."""
    if backends.get(BACKEND_NAME) is not AtomicLocalBackend:
        register_backend(BACKEND_NAME, AtomicLocalBackend)
