"""The training step a checkpoint was saved at, and checkpoints in step
order.

``--resume`` must continue from the latest step, whatever the files'
modification times say: a work dir copied with ``cp`` (or restored from a
backup, or synced) gives its files the times of the copy, so the oldest
checkpoint can look the newest. A step is read from the file's name
(``epoch_N.pth`` / ``iter_N.pth``, as mmengine's ``CheckpointHook`` names
them) and, where names cannot be compared (other names, or ``epoch_`` and
``iter_`` files in one folder), from the checkpoint's ``meta``.
"""
import os
import os.path as osp
import re
from typing import Dict, Iterable, List, Optional, Tuple

from ..fileio.safe_pickle import load_checkpoint_file

_CHECKPOINT_NAME = re.compile(r'^(epoch|iter)_(\d+)\.pth$')


def name_step(path: str) -> Optional[Tuple[str, int]]:
    """The step in the name of ``epoch_N.pth`` / ``iter_N.pth``.

    Args:
        path (str): A checkpoint path.

    Returns:
        tuple[str, int] | None: ``('epoch', N)`` or ``('iter', N)``; None
        for any other name.
    """
    match = _CHECKPOINT_NAME.match(osp.basename(path))
    return (match[1], int(match[2])) if match else None


def step_checkpoints(folder: str) -> List[str]:
    """The ``epoch_N.pth`` / ``iter_N.pth`` files of ``folder``, by name.

    Listed with ``os.listdir``, never a glob pattern: a work dir named
    ``exp[1]`` is a pattern matching ``exp1`` to glob, which then found no
    checkpoint, and ``--resume`` trained from scratch over them.

    Args:
        folder (str): A work dir; a missing one holds none.

    Returns:
        list[str]: Their paths (regular files only), sorted by name.
    """
    if not osp.isdir(folder):
        return []
    return [
        osp.join(folder, name) for name in sorted(os.listdir(folder))
        if name_step(name) is not None
        and osp.isfile(osp.join(folder, name))
    ]


def meta_step(path: str) -> Optional[int]:
    """The iteration saved in a checkpoint's ``meta`` (loads the file).

    mmengine's loops store ``meta['iter']`` (iterations done) in epoch-
    and iteration-based training alike, so it orders any two checkpoints
    of a run.

    Args:
        path (str): A checkpoint file.

    Returns:
        int | None: ``meta['iter']``, or None if the file does not load
        through the restricted loader or holds no such entry.
    """
    try:
        checkpoint = load_checkpoint_file(path, map_location='cpu')
    except Exception:  # noqa: BLE001 - a broken file has no step
        return None
    meta = checkpoint.get('meta') if isinstance(checkpoint, dict) else None
    step = meta.get('iter') if isinstance(meta, dict) else None
    return step if isinstance(step, int) else None


def checkpoint_steps(paths: Iterable[str]) -> Dict[str, int]:
    """A comparable step of each checkpoint.

    The steps in the names when every name is ``epoch_N.pth``, or every
    name ``iter_N.pth``; otherwise ``meta['iter']`` of every file (-1 for
    a file that does not load).

    Args:
        paths (Iterable[str]): Checkpoint files.

    Returns:
        dict[str, int]: Path -> step.
    """
    paths = list(paths)
    named = {path: name_step(path) for path in paths}
    kinds = {step[0] for step in named.values() if step is not None}
    if None not in named.values() and len(kinds) <= 1:
        return {path: step[1] for path, step in named.items()}
    steps = {path: meta_step(path) for path in paths}
    return {path: -1 if step is None else step for path, step in steps.items()}


def by_step(paths: Iterable[str],
            preferred: Optional[str] = None) -> List[str]:
    """Checkpoints, the latest step first.

    Among equal steps ``preferred`` (the ``last_checkpoint`` pointer's
    target) comes first, then the newer modification time: file times
    only break ties, as a copy resets them.

    Args:
        paths (Iterable[str]): Existing checkpoint files.
        preferred (str, optional): The file that wins a tie.

    Returns:
        list[str]: ``paths``, ordered.
    """
    steps = checkpoint_steps(paths)
    return sorted(
        steps,
        key=lambda path:
        (steps[path], path == preferred, os.stat(path).st_mtime_ns),
        reverse=True)
