"""Checkpoint rotation that never leaves fewer than one loadable checkpoint.

mmengine 0.10.7's ``CheckpointHook`` deletes the oldest kept checkpoint
(and the previous best one) *before* it writes the new one: with
``max_keep_ckpts=1`` a SIGKILL, a Ctrl-C or a full disk during the write
leaves no checkpoint at all. :class:`SafeCheckpointHook` runs the same
logic, but every deletion it asks for is only recorded while the new file
is written; the new checkpoint is then read back through the restricted
loader and checked, the ``last_checkpoint`` pointer is replaced atomically,
and only then are the old files deleted (only files inside the work dir:
a resumed run's message hub names the previous best checkpoint by its
old path). ``last_checkpoint`` is never written through a symlink.
Whatever is interrupted when, the work dir keeps at least one complete
checkpoint, and ``--resume``
(:class:`~.checkpoint_recovery_hook.CheckpointRecoveryHook`) finds the
newest one. A divergence guard raising in ``before_save_checkpoint``
(:class:`~.non_finite_loss_hook.NonFiniteLossHook`) stops the save before
anything is written or deleted.
"""
import difflib
import inspect
import os
import os.path as osp
from typing import Any, List, Optional

from mmdet3d.registry import HOOKS
from mmengine.dist import is_main_process
from mmengine.hooks import CheckpointHook

from ...fileio.atomic_file_backend import (BACKEND_NAME, atomic_write,
                                           register_atomic_backend)
from ...fileio.safe_pickle import load_checkpoint_file


class _DeferredRemovals:
    """A file backend whose ``remove`` / ``rmtree`` are only recorded.

    Args:
        backend: The real file backend; everything else is delegated.
    """

    def __init__(self, backend) -> None:
        self.backend = backend
        self.paths: List[str] = []

    def remove(self, path: str) -> None:
        """Record a file to delete later."""
        self.paths.append(str(path))

    def rmtree(self, path: str) -> None:
        """Record a folder (DeepSpeed checkpoint) to delete later."""
        self.paths.append(str(path))

    def __getattr__(self, name: str) -> Any:
        return getattr(self.backend, name)


def _inside(path: str, folder: str) -> bool:
    """Whether local ``path`` lies in ``folder`` (URLs: by prefix)."""
    if '://' in str(path) or '://' in str(folder):
        return str(path).startswith(str(folder).rstrip('/') + '/')
    folder = osp.realpath(folder)
    return osp.commonpath([osp.realpath(path), folder]) == folder


def _real_backend(backend):
    while isinstance(backend, _DeferredRemovals):
        backend = backend.backend
    return backend


@HOOKS.register_module()
class SafeCheckpointHook(CheckpointHook):
    """``CheckpointHook`` that writes and verifies before it deletes.

    Takes every argument of mmengine's ``CheckpointHook``; an argument it
    does not know is refused when the hook is built (mmengine would pass it
    on to ``Runner.save_checkpoint`` and fail at the first save, after a
    whole epoch). ``backend_args`` defaults to the ``atomic_local``
    backend (:mod:`.atomic_file_backend`), so a ``.pth`` on disk is always
    complete.

    Args:
        *args: Positional arguments of ``CheckpointHook``.
        verify (bool): Read every new checkpoint back through the
            restricted loader and check its step before anything is
            deleted. Defaults to True.
        **kwargs: Keyword arguments of ``CheckpointHook``.

    Raises:
        TypeError: For an argument ``CheckpointHook`` does not take.
    """

    def __init__(self, *args, verify: bool = True, **kwargs) -> None:
        known = inspect.signature(CheckpointHook.__init__).parameters
        unknown = sorted(
            key for key in kwargs
            if key not in known or known[key].kind == inspect.Parameter.
            VAR_KEYWORD)
        if unknown:
            hints = {
                key: difflib.get_close_matches(key, list(known), n=1)
                for key in unknown
            }
            described = ', '.join(
                f'{key!r}' + (f' (did you mean {hint[0]!r}?)' if hint else '')
                for key, hint in hints.items())
            raise TypeError(
                f'SafeCheckpointHook: unknown argument {described}; '
                f'CheckpointHook takes {sorted(set(known) - {"self"})}.')
        register_atomic_backend()
        kwargs.setdefault('backend_args', dict(backend=BACKEND_NAME))
        super().__init__(*args, **kwargs)
        self.verify = verify

    def _pointer(self, runner) -> str:
        return osp.join(runner.work_dir, 'last_checkpoint')

    def _read_pointer(self, runner) -> Optional[str]:
        path = self._pointer(runner)
        if not osp.isfile(path):
            return None
        with open(path) as f:
            return f.read().strip() or None

    def _check_written(self, path: str, meta: dict) -> None:
        """Read ``path`` back and compare its step with ``meta``.

        Raises:
            RuntimeError: If it does not load or holds another step.
        """
        try:
            checkpoint = load_checkpoint_file(path, map_location='cpu')
        except Exception as err:
            raise RuntimeError(
                f'SafeCheckpointHook: the checkpoint just written, {path}, '
                f'does not load back ({err}); the previous checkpoints are '
                'kept.') from err
        saved = {k: checkpoint.get('meta', {}).get(k) for k in meta}
        if 'state_dict' not in checkpoint or saved != meta:
            raise RuntimeError(
                f'SafeCheckpointHook: {path} holds meta {saved} and keys '
                f'{sorted(checkpoint)}, expected meta {meta} and a '
                'state_dict; the previous checkpoints are kept.')

    def _finish(self, runner, written: List[str], meta: dict,
                deferred: _DeferredRemovals,
                previous: Optional[str] = None) -> None:
        """Verify the ``written`` files, then delete the deferred ones.

        Args:
            runner (Runner): The runner.
            written (list[str]): Checkpoints just written.
            meta (dict): ``epoch`` and ``iter`` they must hold.
            deferred (_DeferredRemovals): What the save wanted deleted.
            previous (str, optional): The pointer's target before the
                save, restored if a written file fails verification.
        """
        if not is_main_process():
            return
        if self.verify:
            try:
                for path in written:
                    self._check_written(path, meta)
            except RuntimeError:
                pointer = self._pointer(runner)
                if previous is not None:
                    atomic_write(pointer, previous.encode())
                elif osp.isfile(pointer):
                    os.remove(pointer)
                raise
        backend = _real_backend(deferred)
        for path in deferred.paths:
            if path in written:
                continue
            if not _inside(path, runner.work_dir):
                # A resumed message hub names the best checkpoint by the
                # path it had: a moved or copied work dir, or a forged
                # checkpoint, would delete a file elsewhere.
                runner.logger.warning(
                    f'SafeCheckpointHook: not deleting {path}, which lies '
                    f'outside the work dir {runner.work_dir}.')
                continue
            if backend.isfile(path):
                backend.remove(path)
            elif backend.isdir(path):
                backend.rmtree(path)

    def _save_checkpoint_with_step(self, runner, step, meta) -> None:
        """Save ``step``, verify it, update the pointer, then rotate."""
        previous = self._read_pointer(runner) if is_main_process() else None
        # Runner.save_checkpoint adds cfg, seed, ... to ``meta`` in place.
        expected = dict(epoch=meta['epoch'], iter=meta['iter'])
        deferred = _DeferredRemovals(self.file_backend)
        self.file_backend = deferred
        if is_main_process() and osp.islink(self._pointer(runner)):
            # mmengine writes the pointer with open(), which would write
            # through a symlink into its target.
            os.unlink(self._pointer(runner))
        try:
            super()._save_checkpoint_with_step(runner, step, meta)
        finally:
            self.file_backend = deferred.backend
        if is_main_process():
            # mmengine wrote the pointer with open(); make it atomic.
            atomic_write(self._pointer(runner), self.last_ckpt.encode())
        self._finish(runner, [self.last_ckpt], expected, deferred, previous)

    def _best_paths(self) -> List[str]:
        paths = [getattr(self, 'best_ckpt_path', None)]
        paths += list((getattr(self, 'best_ckpt_path_dict', None)
                       or {}).values())
        return [str(p) for p in paths if p]

    def _save_best_checkpoint(self, runner, metrics) -> None:
        """Save a new best checkpoint before deleting the previous best."""
        before = set(self._best_paths())
        deferred = _DeferredRemovals(self.file_backend)
        self.file_backend = deferred
        try:
            super()._save_best_checkpoint(runner, metrics)
        finally:
            self.file_backend = deferred.backend
        new = [p for p in self._best_paths() if p not in before]
        self._finish(runner, new, dict(epoch=runner.epoch, iter=runner.iter),
                     deferred)
