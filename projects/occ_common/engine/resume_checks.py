"""``--resume`` must not silently undo the config's optimizer or schedule.

``Runner.resume`` loads the optimizer's state (every param group's
``lr``, ``momentum``, ``weight_decay`` ...) and each parameter scheduler's
(``__dict__.update``: milestones, gamma, begin / end, the values it starts
from) over the ones just built from the config. An
``optim_wrapper.optimizer.lr`` given with ``--resume`` (or a schedule
edited in the config) therefore changed nothing, and the log said nothing.

:func:`resumed_state_changes` compares the state the config builds with
the one the checkpoint restores: every hyper-parameter of the optimizer's
param groups (``initial_lr`` where a scheduler keeps it) and every
attribute of each scheduler but its progress (:data:`PROGRESS_KEYS`).
``CheckpointMatchHook`` refuses a resume where they differ, naming each
value, so that an override is never dropped without a word.

The training length is the exception: a scheduler whose config names no
``end`` ends with the training, and a resume with a larger ``max_epochs``
keeps the checkpoint's ``end`` (mmengine's behaviour, which the usual
"train on for more epochs" relies on); it is logged as a warning
(:func:`kept_schedule_ends`), since the later steps then do nothing.
Re-running the command of the interrupted run (the same overrides)
resumes as before. To train on with other values, start a new run from
the checkpoint's weights (``load_from=PATH``).
"""
import math
from collections import Counter
from typing import Any, List, Mapping, Sequence

#: Scheduler attributes that are progress, not configuration.
PROGRESS_KEYS = frozenset(
    {'last_step', '_global_step', '_get_value_called_within_step',
     '_last_value'})


def _same(a: Any, b: Any) -> bool:
    """Equal, floats to 1e-12 relative, sequences and Counters by item."""
    if isinstance(a, Counter) or isinstance(b, Counter):
        return Counter(a) == Counter(b)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        try:
            return math.isclose(a, b, rel_tol=1e-12) or (a == b)
        except TypeError:
            return False
    try:
        return bool(a == b)
    except Exception:  # noqa: BLE001 - arrays and other odd values
        return False


def _group_changes(name: str, built: Sequence[Mapping],
                   saved: Sequence[Mapping]) -> List[str]:
    """Differences of the optimizer's param groups (``initial_X`` where a
    scheduler keeps one: ``X`` is then the scheduled value)."""
    if len(built) != len(saved):
        return [f'{name}: {len(saved)} param groups in the checkpoint, '
                f'{len(built)} built from the config']
    changes = []
    for index, (group, old) in enumerate(zip(built, saved)):
        for key, value in group.items():
            if key == 'params' or key.startswith('initial_') or \
                    key not in old:
                continue
            kept = f'initial_{key}'
            if kept in group and kept in old:
                key, value = kept, group[kept]
            if not _same(value, old[key]):
                changes.append(f'{name} param group {index} {key} '
                               f'{old[key]!r} (config: {value!r})')
    return changes


def _optimizer_changes(optim_wrapper, saved: Mapping) -> List[str]:
    wrappers = (dict(optim_wrapper.items())
                if hasattr(optim_wrapper, 'items') else {'': optim_wrapper})
    changes = []
    for name, wrapper in wrappers.items():
        state = saved.get(name, {}) if name else saved
        if 'param_groups' not in state:
            continue
        label = f'optimizer {name}'.strip()
        changes += _group_changes(label, wrapper.optimizer.param_groups,
                                  state['param_groups'])
    return changes


def _entries(config) -> List[Mapping]:
    """A ``param_scheduler`` config as a list of dicts."""
    if isinstance(config, Mapping):
        return [config]
    return list(config or [])


def _scheduler_pairs(schedulers, saved, config):
    """``(label, built, saved states, config entries)`` per optimizer."""
    if isinstance(schedulers, Mapping):
        return [(f'param_scheduler {name}', schedulers[name],
                 saved.get(name, []) if isinstance(saved, Mapping) else [],
                 _entries((config or {}).get(name))) for name in schedulers]
    return [('param_scheduler', schedulers or [], saved or [],
             _entries(config))]


def _scheduler_changes(schedulers, saved, config) -> List[str]:
    changes = []
    for label, built, old, entries in _scheduler_pairs(schedulers, saved,
                                                       config):
        # ``end`` a config leaves out follows the training length:
        # kept_schedule_ends warns about it instead.
        if len(built) != len(old):
            changes.append(f'{label}: {len(old)} schedulers in the '
                           f'checkpoint, {len(built)} in the config')
            continue
        for index, (scheduler, state) in enumerate(zip(built, old)):
            if isinstance(scheduler, Mapping):
                continue  # not built: nothing to compare
            named = entries[index] if index < len(entries) else {}
            for key, value in scheduler.state_dict().items():
                if key in PROGRESS_KEYS or key not in state or (
                        key == 'end' and 'end' not in named):
                    continue
                if not _same(value, state[key]):
                    changes.append(
                        f'{label}[{index}] ({type(scheduler).__name__}) '
                        f'{key} {state[key]!r} (config: {value!r})')
    return changes


def _built(runner):
    """The Runner's built schedulers, or None (not built yet)."""
    schedulers = getattr(runner, 'param_schedulers', None)
    if not schedulers:
        return None
    first = next(iter(schedulers))
    if isinstance(schedulers, Mapping):
        first = next(iter(schedulers[first]), None)
    return None if isinstance(first, Mapping) else schedulers


def kept_schedule_ends(runner, checkpoint: Mapping) -> List[str]:
    """Schedulers whose ``end`` the resume keeps though the training
    length changed (the warnings ``CheckpointMatchHook`` logs).

    A scheduler whose config entry names no ``end`` ends where the
    training does (the Runner sets it from ``max_epochs`` / ``max_iters``),
    and ``Runner.resume`` restores the checkpoint's ``end`` over it: a run
    resumed with a larger ``max_epochs`` never takes the scheduler's later
    steps (the toy config's lr stayed 0.5 where an uninterrupted run
    halved it to 0.25). Setting the new ``end`` would not repair it (the
    steps between were already skipped), so the resume goes on as
    mmengine resumes, with a warning.

    Args:
        runner (Runner): The runner, its schedulers built.
        checkpoint (Mapping): The checkpoint being resumed.

    Returns:
        list[str]: One line per such scheduler.
    """
    schedulers = _built(runner)
    saved = checkpoint.get('param_schedulers')
    if schedulers is None or saved is None:
        return []
    kept = []
    for label, built, old, entries in _scheduler_pairs(
            schedulers, saved, runner.cfg.get('param_scheduler')):
        for index, (scheduler, state) in enumerate(zip(built, old)):
            if isinstance(scheduler, Mapping):
                continue
            end = getattr(scheduler, 'end', None)
            if 'end' not in state or state['end'] == end:
                continue
            kept.append(f'{label}[{index}] ({type(scheduler).__name__}) '
                        f'keeps the checkpoint\'s end {state["end"]} (the '
                        f'training length now gives {end}): a resumed '
                        'schedule is not extended, its later steps do '
                        'nothing. Give the scheduler an explicit end, or '
                        'train the longer schedule from the start')
    return kept


def resumed_state_changes(runner, checkpoint: Mapping) -> List[str]:
    """What resuming ``checkpoint`` would set other than the config says.

    Call it when the Runner has built its optimizer and schedulers and
    loaded ``checkpoint``, before resuming from it
    (``after_load_checkpoint``).

    Args:
        runner (Runner): The runner.
        checkpoint (Mapping): The checkpoint being resumed.

    Returns:
        list[str]: One item per value the checkpoint would restore over
        the config's: ``'optimizer param group 0 initial_lr 0.5 (config:
        0.1)'``, ``'param_scheduler[0] (MultiStepLR) milestones ...'``.
    """
    changes = []
    optim_wrapper = getattr(runner, 'optim_wrapper', None)
    if checkpoint.get('optimizer') is not None and \
            optim_wrapper is not None and not isinstance(optim_wrapper,
                                                         Mapping):
        changes += _optimizer_changes(optim_wrapper, checkpoint['optimizer'])
    schedulers = _built(runner)
    if checkpoint.get('param_schedulers') is not None and schedulers:
        changes += _scheduler_changes(schedulers,
                                      checkpoint['param_schedulers'],
                                      runner.cfg.get('param_scheduler'))
    return changes


__all__ = ['PROGRESS_KEYS', 'kept_schedule_ends', 'resumed_state_changes']
