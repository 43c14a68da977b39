"""Write no checkpoint once the work dir's lock is another run's.

``tools/train.py`` runs its Runner inside
:func:`~projects.occ_common.engine.run_lock.hold_work_dir`, which takes
the work dir's lock (a second run into a work dir in use refuses, and a
run without ``--resume`` never overwrites an earlier run's checkpoints)
and adds this hook. Two runs taking over one stale lock at the same
moment could both believe they hold it; the lock's heartbeat re-reads it
every 30 s, and this hook re-reads it before every checkpoint, so the run
that lost stops before it writes anything.
"""
from mmdet3d.registry import HOOKS
from mmengine.hooks import Hook

from ..run_lock import held_lock


@HOOKS.register_module()
class WorkDirLockHook(Hook):
    """Check the work dir's lock before each checkpoint (and each epoch).

    Does nothing in a process that holds no lock on the work dir (a rank
    but 0, or a Runner not started by ``tools/train.py``).
    """

    priority = 'HIGHEST'

    def _check(self, runner) -> None:
        lock = held_lock(runner.work_dir)
        if lock is not None:
            lock.check_held()

    def before_train_epoch(self, runner) -> None:
        """Stop a run that lost its lock (see the module docstring)."""
        self._check(runner)

    def before_save_checkpoint(self, runner, checkpoint: dict) -> None:
        """Write nothing once the lock is no longer this run's.

        Raises:
            WorkDirInUseError: Naming the lock and its new owner.
        """
        self._check(runner)
