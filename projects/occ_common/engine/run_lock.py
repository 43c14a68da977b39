"""One training run at a time in a work dir: ``<work_dir>/run.lock``.

Two runs started into one work dir both exited 0, and the second had
overwritten the first one's checkpoints. :class:`RunLock` is a file
created with ``O_CREAT | O_EXCL`` (atomic on local and NFS file systems)
holding the owner's host, pid, process start time, a random token and its
command line; a second run finds it and refuses, naming the owner.

A crashed or killed run cannot release its lock, so a lock is **stale**,
and is taken over with a warning, when its owner is gone:

* on this host: no process has its pid, or the process with that pid
  started at another time (the pid was reused; Linux's
  ``/proc/<pid>/stat``), or it is this very process (a Runner of this
  process that ended with an exception);
* on another host (a work dir on a shared file system): the lock's
  modification time, which the owner touches every
  :data:`HEARTBEAT_SECONDS`, is older than :data:`STALE_SECONDS`.

So ``--resume`` after a crash or a SIGKILL just works, on the same or
another machine, and a lock is never left forever.

Two runs taking over one stale lock at the same moment could both believe
they hold it; the owner therefore re-reads its token at every heartbeat
and before every checkpoint it writes (:meth:`RunLock.check_held`), so
the one that lost stops before it writes anything.
"""
import contextlib
import json
import os
import os.path as osp
import secrets
import socket
import sys
import threading
import time
import warnings
from typing import Dict, Iterator, List, Optional

#: Name of the lock file in the work dir.
LOCK_NAME = 'run.lock'
#: The owner touches its lock this often (seconds).
HEARTBEAT_SECONDS = 30.0
#: A lock of another host untouched this long is stale (ten heartbeats,
#: and minutes of clock skew between hosts to spare).
STALE_SECONDS = 300.0


class WorkDirError(RuntimeError):
    """A training run may not write into its work dir (the message says
    why and what to do, in one line)."""


class WorkDirInUseError(WorkDirError):
    """Another live run holds the work dir's lock."""


def _start_time(pid: int) -> Optional[str]:
    """When process ``pid`` started, in clock ticks since boot (field 22
    of ``/proc/<pid>/stat``); None where there is no ``/proc``."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            stat = f.read()
    except OSError:
        return None
    # The command name (field 2) may hold spaces: count after its ')'.
    return stat[stat.rindex(')') + 2:].split()[19]


def process_alive(pid: int) -> bool:
    """Whether a process with ``pid`` runs on this host (another user's
    counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's process
    return True


def owner_gone(owner: dict, mtime: float,
               now: Optional[float] = None) -> Optional[str]:
    """Why the run that wrote lock content ``owner`` is gone, or None.

    Args:
        owner (dict): The lock's content (``host``, ``pid``, ``start``).
        mtime (float): The lock file's modification time.
        now (float, optional): The time to compare with. Defaults to
            ``time.time()``.

    Returns:
        str | None: The reason the lock is stale (see the module doc), or
        None if its owner may still run.
    """
    now = time.time() if now is None else now
    host, pid = owner.get('host'), owner.get('pid')
    if host != socket.gethostname():
        age = now - mtime
        if age > STALE_SECONDS:
            return (f'its owner on host {host} has not touched it for '
                    f'{age:.0f} s (more than {STALE_SECONDS:.0f} s)')
        return None
    if not isinstance(pid, int):
        return 'it names no process'
    if pid == os.getpid():
        return 'it is this process\'s own, left by a run that failed'
    if not process_alive(pid):
        return f'no process {pid} runs on this host'
    start = _start_time(pid)
    if start is not None and owner.get('start') not in (None, start):
        return f'process {pid} is another one than its owner (pid reused)'
    return None


class RunLock:
    """The lock of one work dir, held by this process.

    Args:
        work_dir (str): The work dir (created if needed).
    """

    def __init__(self, work_dir: str) -> None:
        self.work_dir = work_dir
        self.path = osp.join(work_dir, LOCK_NAME)
        self.token = secrets.token_hex(8)
        self.lost: Optional[str] = None
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    def _content(self) -> bytes:
        return json.dumps(dict(
            host=socket.gethostname(), pid=os.getpid(),
            start=_start_time(os.getpid()), token=self.token,
            started=time.strftime('%Y-%m-%d %H:%M:%S'),
            command=' '.join(sys.argv)[:300])).encode()

    def _read(self) -> Optional[dict]:
        """The lock's content; ``{}`` if unreadable, None if absent."""
        try:
            fd = os.open(self.path, os.O_RDONLY | getattr(os, 'O_NOFOLLOW',
                                                          0))
        except FileNotFoundError:
            return None
        except OSError:
            return {}  # a symlink or worse: nobody's lock
        with os.fdopen(fd) as f:
            try:
                content = json.load(f)
            except ValueError:
                return {}
        return content if isinstance(content, dict) else {}

    def _create(self) -> bool:
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL,
                         0o644)
        except FileExistsError:
            return False
        with os.fdopen(fd, 'wb') as f:
            f.write(self._content())
        return True

    def acquire(self) -> Optional[str]:
        """Take the lock, or take over a stale one.

        Returns:
            str | None: Why a stale lock was taken over (for a warning),
            or None.

        Raises:
            WorkDirInUseError: If a live run holds it, naming the run and
                what to do (one line).
        """
        os.makedirs(self.work_dir, exist_ok=True)
        taken_over = None
        for _ in range(3):  # the lock may vanish between the steps
            if self._create():
                break
            owner = self._read()
            if owner is None:
                continue
            try:
                mtime = os.lstat(self.path).st_mtime
            except FileNotFoundError:
                continue
            gone = owner_gone(owner, mtime) if owner else \
                'it is not a lock file of this library'
            if gone is None:
                raise WorkDirInUseError(
                    f'work dir {self.work_dir} is in use by another run '
                    f'(pid {owner.get("pid")} on host {owner.get("host")}, '
                    f'since {owner.get("started")}: '
                    f'{owner.get("command", "?")}); wait for it to end or '
                    f'pass another --work-dir (if that run is gone, delete '
                    f'{self.path}).')
            os.replace(self._temporary(), self.path)
            taken_over = (f'took over {self.path} of a run that did not '
                          f'release it ({gone})')
            break
        else:
            raise WorkDirInUseError(
                f'work dir {self.work_dir}: could not create {self.path}.')
        self._start_heartbeat()
        return taken_over

    def _temporary(self) -> str:
        """Our content in a fresh file beside the lock, to replace it."""
        temp = f'{self.path}.{os.getpid()}.{self.token}.tmp'
        with open(temp, 'wb') as f:
            f.write(self._content())
        return temp

    def check_held(self) -> None:
        """Raise if the lock is no longer this run's.

        Raises:
            WorkDirInUseError: If another run took it over (or it was
                deleted), naming the lock.
        """
        if self.lost is None:
            owner = self._read() or {}
            if owner.get('token') != self.token:
                self.lost = (f'{self.path} now belongs to pid '
                             f'{owner.get("pid")} on host '
                             f'{owner.get("host")}' if owner else
                             f'{self.path} was removed')
        if self.lost is not None:
            raise WorkDirInUseError(
                f'work dir {self.work_dir}: this run lost its lock '
                f'({self.lost}); stopping before it writes anything.')

    def _start_heartbeat(self) -> None:

        def beat():
            while not self._stop.wait(HEARTBEAT_SECONDS):
                try:
                    self.check_held()
                    os.utime(self.path)
                except (WorkDirInUseError, OSError):
                    return  # ``lost`` says why; the hooks raise it

        self._thread = threading.Thread(
            target=beat, name='RunLock heartbeat', daemon=True)
        self._thread.start()

    def release(self) -> None:
        """Stop the heartbeat and delete the lock if it is still ours."""
        self._stop.set()
        owner = self._read() or {}
        if owner.get('token') == self.token:
            try:
                os.remove(self.path)
            except FileNotFoundError:
                pass
        elif self.lost is None:
            warnings.warn(f'{self.path} was no longer this run\'s lock.')


#: The locks this process holds, by the work dir's real path.
_HELD: Dict[str, RunLock] = {}


def held_lock(work_dir: str) -> Optional[RunLock]:
    """The lock this process holds on ``work_dir``, if any."""
    return _HELD.get(osp.realpath(work_dir))


def earlier_run_files(work_dir: str) -> List[str]:
    """The checkpoints and pointer of an earlier run in ``work_dir``.

    Args:
        work_dir (str): A work dir.

    Returns:
        list[str]: Their base names (``epoch_1.pth``, ...,
        ``last_checkpoint``).
    """
    from .checkpoint_steps import step_checkpoints
    found = [osp.basename(path) for path in step_checkpoints(work_dir)]
    if osp.lexists(osp.join(work_dir, 'last_checkpoint')):
        found.append('last_checkpoint')
    return found


def _take(work_dir: str, resume: bool, log) -> Optional[str]:
    """Rank 0's part of :func:`hold_work_dir`; an error message or None."""
    lock = RunLock(work_dir)
    try:
        taken_over = lock.acquire()
    except WorkDirError as err:
        return str(err)
    if taken_over:
        log(f'{taken_over}.')
    earlier = [] if resume else earlier_run_files(work_dir)
    if earlier:
        lock.release()
        shown = ', '.join(earlier[:4]) + (', ...' if len(earlier) > 4 else
                                          '')
        return (f'work dir {work_dir} holds the checkpoints of an earlier '
                f'run ({shown}), which this run would overwrite: pass '
                '--resume to continue that run, another --work-dir for a '
                'new one, or move them away.')
    _HELD[osp.realpath(work_dir)] = lock
    return None


@contextlib.contextmanager
def hold_work_dir(work_dir: str, resume: bool = False,
                  log=warnings.warn) -> Iterator[Optional[RunLock]]:
    """Own ``work_dir`` for a training run: ``tools/train.py`` builds and
    runs its Runner inside this block.

    Rank 0 takes the lock (taking over a stale one, see the module doc)
    and, unless the run resumes, refuses a work dir that holds an earlier
    run's checkpoints, which the run would overwrite. Its verdict is
    broadcast, so every rank stops alike. The lock is released when the
    block ends, however it ends.

    Args:
        work_dir (str): The run's work dir (created if needed).
        resume (bool): Whether the run resumes (``--resume``): the work
            dir's checkpoints are then its own. Defaults to False.
        log (callable): Takes the line saying a stale lock was taken over.
            Defaults to ``warnings.warn``.

    Yields:
        RunLock | None: Rank 0's lock; None on the other ranks.

    Raises:
        WorkDirError: On every rank, in one line: the work dir is in use
            by a live run, or holds an earlier run's checkpoints.
    """
    from mmengine.dist import broadcast_object_list, get_dist_info
    rank, world_size = get_dist_info()
    verdict = [_take(work_dir, resume, log) if rank == 0 else None]
    if world_size > 1:
        broadcast_object_list(verdict, src=0)
    if verdict[0] is not None:
        raise WorkDirError(verdict[0])
    lock = held_lock(work_dir) if rank == 0 else None
    try:
        yield lock
    finally:
        if lock is not None:
            _HELD.pop(osp.realpath(work_dir), None)
            lock.release()


__all__ = [
    'HEARTBEAT_SECONDS', 'LOCK_NAME', 'RunLock', 'STALE_SECONDS',
    'WorkDirError', 'WorkDirInUseError', 'earlier_run_files',
    'held_lock', 'hold_work_dir', 'owner_gone', 'process_alive'
]
