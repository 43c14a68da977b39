"""``--resume`` must not silently undo the config's optimizer or schedule.

``Runner.resume`` loads the optimizer's state (every param group's
``lr``, ``momentum``, ``weight_decay`` ...) and each parameter scheduler's
(``__dict__.update``: milestones, gamma, begin / end, the values it starts
from) over the ones just built from the config. An
``optim_wrapper.optimizer.lr`` given with ``--resume`` (or a schedule
edited in the config) therefore changed nothing, and the log said nothing.

:func:`resumed_state_changes` compares the state the config builds with
the one the checkpoint restores: every hyper-parameter of the optimizer's
param groups (``initial_lr`` where a scheduler keeps it), and of each
scheduler the values it starts from and every argument its config entry
names. ``begin`` / ``end`` a config leaves out follow the training length,
so a resume that raises ``max_epochs`` passes (the restored scheduler
keeps its old end, as in mmengine). ``CheckpointMatchHook`` refuses a
resume where they differ, naming each value, so that an override is never
dropped without a word. Re-running the command of the interrupted run
(the same overrides) resumes as before. To train on with other values,
start a new run from the checkpoint's weights (``load_from=PATH``).
"""
import math
from collections import Counter
from typing import Any, List, Mapping, Sequence

#: Scheduler attributes compared whatever the config names: the values
#: the schedule starts from (the optimizer's ``lr`` ... times the group's
#: multiplier).
ALWAYS_COMPARED = ('base_values', )


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


def _scheduler_changes(schedulers, saved, config) -> List[str]:
    if isinstance(schedulers, Mapping):
        pairs = [(f'param_scheduler {name}', schedulers[name],
                  saved.get(name, []) if isinstance(saved, Mapping) else [],
                  _entries((config or {}).get(name)))
                 for name in schedulers]
    else:
        pairs = [('param_scheduler', schedulers or [], saved or [],
                  _entries(config))]
    changes = []
    for label, built, old, entries in pairs:
        if len(built) != len(old):
            changes.append(f'{label}: {len(old)} schedulers in the '
                           f'checkpoint, {len(built)} in the config')
            continue
        for index, (scheduler, state) in enumerate(zip(built, old)):
            if isinstance(scheduler, Mapping):
                continue  # not built: nothing to compare
            named = entries[index] if index < len(entries) else {}
            compared = set(ALWAYS_COMPARED) | (set(named) - {'type'})
            for key, value in scheduler.state_dict().items():
                if key not in compared or key not in state:
                    continue
                if not _same(value, state[key]):
                    changes.append(
                        f'{label}[{index}] ({type(scheduler).__name__}) '
                        f'{key} {state[key]!r} (config: {value!r})')
    return changes


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
    schedulers = getattr(runner, 'param_schedulers', None)
    if checkpoint.get('param_schedulers') is not None and schedulers and \
            not isinstance(next(iter(schedulers)), Mapping):
        changes += _scheduler_changes(schedulers,
                                      checkpoint['param_schedulers'],
                                      runner.cfg.get('param_scheduler'))
    return changes


__all__ = ['ALWAYS_COMPARED', 'resumed_state_changes']
