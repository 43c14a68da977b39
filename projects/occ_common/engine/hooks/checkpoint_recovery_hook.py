"""Resume from the latest complete checkpoint, whatever a crash or a copy
left, and never go back in time.

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
- points ``last_checkpoint`` at the complete checkpoint of the latest
  step among the ``epoch_*.pth`` / ``iter_*.pth`` files and the pointer's
  target ("complete": it loads through the restricted loader). Steps come
  from the names or the checkpoints' ``meta``
  (:mod:`~projects.occ_common.engine.checkpoint_steps`); a valid pointer
  wins a tie, and file times only break the remaining ties. Ordering by
  modification time resumed a work dir copied with ``cp`` (``epoch_1.pth``
  copied last) from epoch 1 and then overwrote ``epoch_2.pth`` and
  ``epoch_3.pth``;
- refuses to resume if checkpoints exist but none is complete, naming each
  and its problem, instead of silently training from scratch.

Before a resume from a named file (``--resume PATH``) it refuses, naming
the files, if the work dir holds complete checkpoints of later steps than
``PATH``'s, which the resumed run would overwrite.
"""
import os
import os.path as osp
from typing import List, Optional

from mmdet3d.registry import HOOKS
from mmengine.dist import barrier, is_main_process
from mmengine.hooks import Hook

from ...fileio.atomic_file_backend import atomic_write, is_temporary_file
from ...fileio.safe_pickle import load_checkpoint_file
from ..checkpoint_steps import (by_step, checkpoint_steps, name_step,
                                step_checkpoints)
from ..run_lock import process_alive


def _same_file(a: str, b: str) -> bool:
    return osp.realpath(a) == osp.realpath(b)


def checkpoint_candidates(folder: str,
                          extra: Optional[str] = None) -> List[str]:
    """``epoch_N.pth`` / ``iter_N.pth`` of ``folder`` (and ``extra``),
    the latest step first.

    Args:
        folder (str): Where the checkpoints are.
        extra (str, optional): Another file to consider (the pointer's
            target), if it exists; it wins a tie of steps.

    Returns:
        list[str]: Paths, the latest step first (see
        :func:`~projects.occ_common.engine.checkpoint_steps.by_step`).
    """
    found = step_checkpoints(folder)
    if extra and osp.isfile(extra):
        # The pointer may name a file of the folder by another spelling.
        found = [path for path in found if not _same_file(path, extra)]
        found.append(extra)
    return by_step(found, preferred=extra)


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
    """The complete checkpoint of ``folder`` of the latest step (see the
    module doc).

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


def later_checkpoints(work_dir: str, resume_from: str) -> List[str]:
    """Complete checkpoints of ``work_dir`` of a later step than
    ``resume_from``: what a run resumed from it would overwrite.

    Args:
        work_dir (str): The Runner's work dir.
        resume_from (str): The checkpoint the run resumes from.

    Returns:
        list[str]: Their paths, the earliest step first.
    """
    found = [
        path for path in step_checkpoints(work_dir)
        if not _same_file(path, resume_from)
    ]
    if not osp.isfile(resume_from):  # a URL: only its name can tell
        own = name_step(resume_from)
        found = [
            path for path in found
            if own is not None and name_step(path)[0] == own[0]
        ]
    steps = checkpoint_steps(found + [resume_from])
    if steps[resume_from] < 0:
        return []  # it does not load: the Runner's load says why
    later = [path for path in found if steps[path] > steps[resume_from]]
    return sorted((path for path in later if checkpoint_problem(path) is None),
                  key=steps.get)


def _writer_alive(name: str) -> bool:
    """Whether the process that writes temporary file ``name`` runs."""
    pid = int(name.rsplit('.', 3)[1])
    return pid != os.getpid() and process_alive(pid)


def repair_work_dir(work_dir: str) -> List[str]:
    """Remove stale temporary files and point ``last_checkpoint`` at the
    complete checkpoint of the latest step.

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
                actions.append(f'last_checkpoint now names the complete '
                               f'checkpoint of the latest step {path} '
                               f'({was})')
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


def check_no_later_checkpoint(work_dir: str, resume_from: str) -> None:
    """Refuse to resume from ``resume_from`` if that would overwrite
    checkpoints of later steps in ``work_dir``.

    Args:
        work_dir (str): The Runner's work dir.
        resume_from (str): The file named by ``--resume PATH``.

    Raises:
        RuntimeError: Naming ``resume_from`` and the later checkpoints.
    """
    later = later_checkpoints(work_dir, resume_from)
    if later:
        raise RuntimeError(
            f'--resume {resume_from}: {work_dir} holds checkpoints of later '
            f'steps ({", ".join(later)}), which the resumed run would '
            'overwrite. Resume from the latest with --resume (no path), or '
            'move those files out of the work dir, or pass another '
            '--work-dir.')


@HOOKS.register_module()
class CheckpointRecoveryHook(Hook):
    """Repair the work dir before the Runner resumes from it.

    Listed in ``custom_hooks`` of ``configs/_base_/default_runtime.py``.
    Acts only when the config asks to resume: without naming a file
    (``resume=True``, ``load_from=None``: ``tools/train.py --resume``) it
    repairs the work dir (:func:`repair_work_dir`); from a named file
    (``--resume PATH``) it only checks that no later checkpoint would be
    overwritten (:func:`check_no_later_checkpoint`). Evaluating or
    training elsewhere never touches a work dir. Only rank 0 touches the
    disk; the other ranks wait for it, since every rank reads
    ``last_checkpoint`` when resuming.
    """

    priority = 'VERY_HIGH'

    def before_run(self, runner) -> None:
        """Clean up or check ``runner.work_dir`` (see the class doc)."""
        cfg = runner.cfg
        if not cfg.get('resume', False):
            return
        load_from = cfg.get('load_from')
        if is_main_process():
            if load_from is not None:
                check_no_later_checkpoint(runner.work_dir, load_from)
            else:
                for action in repair_work_dir(runner.work_dir):
                    runner.logger.warning(
                        f'CheckpointRecoveryHook: {action}.')
        barrier()
