"""Resume from the newest complete checkpoint, whatever a crash left.

A run can be killed at any point of a save
(:class:`~.safe_checkpoint_hook.SafeCheckpointHook` writes the new file,
verifies it, points ``last_checkpoint`` at it, then deletes old ones), and
mmengine's auto-resume trusts ``last_checkpoint`` alone: it restarts from
scratch when the pointer is missing (a kill between the first
``epoch_N.pth`` and the first pointer) and fails on a pointer that is empty
or names a deleted or truncated file. Before an auto-resume (``--resume``
without a path; ``before_run`` comes first in ``Runner.train``) this hook

- removes the temporary files of interrupted atomic writes whose writer
  is no longer running;
- points ``last_checkpoint`` at the newest complete checkpoint among the
  ``epoch_*.pth`` / ``iter_*.pth`` files and the pointer's target
  ("complete": it loads through the restricted loader), newest first by
  modification time, then step;
- refuses to resume if checkpoints exist but none is complete, naming each
  and its problem, instead of silently training from scratch.
"""
import glob
import os
import os.path as osp
import re
from typing import List, Optional, Tuple

from mmdet3d.registry import HOOKS
from mmengine.dist import barrier, is_main_process
from mmengine.hooks import Hook

from ..utils.safe_pickle import load_checkpoint_file
from .atomic_file_backend import atomic_write, is_temporary_file

_CHECKPOINT_NAME = re.compile(r'^(epoch|iter)_(\d+)\.pth$')


def _age_key(path: str) -> Tuple[int, int]:
    """Newer first by modification time, then by the step in the name."""
    match = _CHECKPOINT_NAME.match(osp.basename(path))
    return os.stat(path).st_mtime_ns, int(match[2]) if match else -1


def checkpoint_candidates(folder: str,
                          extra: Optional[str] = None) -> List[str]:
    """``epoch_N.pth`` / ``iter_N.pth`` of ``folder`` (and ``extra``),
    newest first.

    Args:
        folder (str): Where the checkpoints are.
        extra (str, optional): Another file to consider (the pointer's
            target), if it exists.

    Returns:
        list[str]: Paths, newest first.
    """
    found = {
        path
        for path in glob.glob(osp.join(folder, '*.pth'))
        if _CHECKPOINT_NAME.match(osp.basename(path)) and osp.isfile(path)
    }
    if extra and osp.isfile(extra):
        found.add(extra)
    return sorted(found, key=_age_key, reverse=True)


def checkpoint_problem(path: str) -> Optional[str]:
    """Why ``path`` cannot be resumed from, or None if it loads.

    Args:
        path (str): A checkpoint file.

    Returns:
        str | None: The loader's error message, or None.
    """
    try:
        checkpoint = load_checkpoint_file(path, map_location='cpu')
    except Exception as err:  # noqa: BLE001 - every failure disqualifies
        return f'{type(err).__name__}: {err}'
    if not isinstance(checkpoint, dict) or 'meta' not in checkpoint:
        return f'holds no Runner checkpoint (keys {sorted(checkpoint)})'
    return None


def newest_checkpoint(folder: str,
                      extra: Optional[str] = None) -> Optional[str]:
    """The newest complete checkpoint of ``folder`` (see the module doc).

    Args:
        folder (str): Where the checkpoints are.
        extra (str, optional): Another candidate (the pointer's target).

    Returns:
        str | None: Its path, or None if no candidate loads.
    """
    for path in checkpoint_candidates(folder, extra):
        if checkpoint_problem(path) is None:
            return path
    return None


def _writer_alive(name: str) -> bool:
    """Whether the process that writes temporary file ``name`` runs."""
    pid = int(name.rsplit('.', 3)[1])
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's process
    return True


def repair_work_dir(work_dir: str) -> List[str]:
    """Remove stale temporary files and point ``last_checkpoint`` at the
    newest complete checkpoint.

    Args:
        work_dir (str): The Runner's work dir.

    Returns:
        list[str]: What was done, one line each (empty if nothing).

    Raises:
        RuntimeError: If checkpoints exist but none of them loads.
    """
    actions = []
    if not osp.isdir(work_dir):
        return actions
    for name in sorted(os.listdir(work_dir)):
        if is_temporary_file(name) and not _writer_alive(name):
            os.remove(osp.join(work_dir, name))
            actions.append(f'removed the partial write {name}')
    pointer = osp.join(work_dir, 'last_checkpoint')
    target, was = None, 'there was no pointer'
    if osp.isfile(pointer):
        with open(pointer) as f:
            target = f.read().strip() or None
        was = f'it named {target}' if target else 'it was empty'
    problems = []
    for path in checkpoint_candidates(work_dir, target):
        problem = checkpoint_problem(path)
        if problem is None:
            if path != target:
                atomic_write(pointer, path.encode())
                actions.append(f'last_checkpoint now names the newest '
                               f'complete checkpoint {path} ({was})')
            for skipped, why in problems:
                actions.append(f'skipped {skipped}: {why}')
            return actions
        problems.append((path, problem))
    if problems:
        listed = '; '.join(f'{path}: {why}' for path, why in problems)
        raise RuntimeError(
            f'--resume: no checkpoint in {work_dir} is complete ({listed}). '
            'Remove them to train from scratch, or resume from another '
            'file with --resume PATH.')
    if osp.isfile(pointer):
        os.remove(pointer)
        actions.append(f'removed last_checkpoint ({was}), as no checkpoint '
                       'is left')
    actions.append(f'no checkpoint in {work_dir}: training starts from '
                   'scratch')
    return actions


@HOOKS.register_module()
class CheckpointRecoveryHook(Hook):
    """Repair the work dir before the Runner auto-resumes from it.

    Listed in ``custom_hooks`` of ``configs/_base_/default_runtime.py``.
    Acts only when the config asks to resume without naming a file
    (``resume=True``, ``load_from=None``: ``tools/train.py --resume``), so
    evaluating or training elsewhere never touches a work dir. Only rank 0
    touches the disk; the other ranks wait for it, since every rank reads
    ``last_checkpoint`` when resuming.
    """

    priority = 'VERY_HIGH'

    def before_run(self, runner) -> None:
        """Clean up ``runner.work_dir`` (see :func:`repair_work_dir`)."""
        cfg = runner.cfg
        if not cfg.get('resume', False) or cfg.get('load_from') is not None:
            return
        if is_main_process():
            for action in repair_work_dir(runner.work_dir):
                runner.logger.warning(f'CheckpointRecoveryHook: {action}.')
        barrier()
