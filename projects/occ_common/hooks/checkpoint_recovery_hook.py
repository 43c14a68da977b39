"""Clean up after a crash while a checkpoint was being written.

With :mod:`.atomic_file_backend` a ``.pth`` on disk is always complete, but
two traces of a crash can remain:

- a temporary file of an interrupted atomic write;
- mmengine 0.10.7's ``CheckpointHook`` writes the ``last_checkpoint``
  pointer with a plain ``open(..., 'w')``; a kill between its truncation
  and its write leaves it empty, and ``--resume`` then tries to load ``''``.

Before the Runner loads or resumes (``before_run`` comes first in
``Runner.train``) this hook removes the temporary files of the work dir
and, if ``last_checkpoint`` is empty or names a file that is gone, points
it atomically at the newest ``epoch_*.pth`` / ``iter_*.pth`` left, or
removes it if there is none (training then starts afresh).
"""
import glob
import os
import os.path as osp
import re
from typing import Optional

from mmdet3d.registry import HOOKS
from mmengine.dist import barrier, is_main_process
from mmengine.hooks import Hook

from .atomic_file_backend import atomic_write, is_temporary_file

_CHECKPOINT_NAME = re.compile(r'^(epoch|iter)_(\d+)\.pth$')


def newest_checkpoint(folder: str) -> Optional[str]:
    """The most recently written ``epoch_N.pth`` / ``iter_N.pth``.

    Args:
        folder (str): Where the checkpoints are.

    Returns:
        str | None: Its path, or None if the folder has none.
    """
    found = [
        path for path in glob.glob(osp.join(folder, '*.pth'))
        if _CHECKPOINT_NAME.match(osp.basename(path)) and osp.isfile(path)
    ]
    if not found:
        return None
    # Equal times (a coarse clock) fall back to the larger step.
    return max(found,
               key=lambda p: (os.stat(p).st_mtime_ns,
                              int(_CHECKPOINT_NAME.match(osp.basename(p))[2])))


def repair_work_dir(work_dir: str) -> list:
    """Remove stale temporary files and fix ``last_checkpoint``.

    Args:
        work_dir (str): The Runner's work dir.

    Returns:
        list[str]: What was done, one line each (empty if nothing).
    """
    actions = []
    if not osp.isdir(work_dir):
        return actions
    for name in sorted(os.listdir(work_dir)):
        if is_temporary_file(name):
            os.remove(osp.join(work_dir, name))
            actions.append(f'removed the partial write {name}')
    pointer = osp.join(work_dir, 'last_checkpoint')
    if not osp.isfile(pointer):
        return actions
    with open(pointer) as f:
        target = f.read().strip()
    if target and osp.isfile(target):
        return actions
    newest = newest_checkpoint(work_dir)
    problem = 'is empty' if not target else f'names a missing file {target}'
    if newest is None:
        os.remove(pointer)
        actions.append(f'removed last_checkpoint, which {problem}, as no '
                       'checkpoint is left')
    else:
        atomic_write(pointer, newest.encode())
        actions.append(f'last_checkpoint {problem}; it now names {newest}')
    return actions


@HOOKS.register_module()
class CheckpointRecoveryHook(Hook):
    """Repair the work dir before the Runner resumes from it.

    Listed in ``custom_hooks`` of ``configs/_base_/default_runtime.py``.
    Only rank 0 touches the disk; the other ranks wait for it, since every
    rank reads ``last_checkpoint`` when resuming.
    """

    priority = 'VERY_HIGH'

    def before_run(self, runner) -> None:
        """Clean up ``runner.work_dir`` (see :func:`repair_work_dir`)."""
        if is_main_process():
            for action in repair_work_dir(runner.work_dir):
                runner.logger.warning(f'CheckpointRecoveryHook: {action}.')
        barrier()
