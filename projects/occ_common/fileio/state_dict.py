"""A checkpoint's state dict, and how it differs from a module's.

One unwrapping and one comparison for every checkpoint the library loads
into a model: a trained model (:func:`projects.occ_common.apis.init_model`,
``tools/test.py``'s ``CheckpointMatchHook``) and the pretrained weights of
a part (:mod:`projects.occ_common.models.pretrained`).
"""
import re
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

#: A comparison's report: key lists by kind of difference.
REPORT_KEYS = ('ignored', 'allowed_missing', 'unexpected', 'missing',
               'shape')


def unwrap_state_dict(loaded: Any,
                      source: str,
                      prefix: Optional[str] = None) -> Dict[str, Any]:
    """The state dict a loaded checkpoint holds.

    Args:
        loaded (object): What the file held: a Runner checkpoint
            (``dict(state_dict=...)``), a ``dict(model=...)`` file or a
            bare state dict.
        source (str): The checkpoint's name, for the messages.
        prefix (str, optional): Keep only keys starting with it, stripped
            (``'backbone.'`` for a detector's file). Defaults to None.

    Returns:
        dict: Key -> value, with DDP's ``module.`` prefix removed.

    Raises:
        ValueError: If ``loaded`` holds no state dict, or no key starts with
            ``prefix``; naming ``source``.
    """
    state = loaded
    for key in ('state_dict', 'model'):
        if isinstance(state, Mapping) and isinstance(state.get(key),
                                                     Mapping):
            state = state[key]
            break
    if not isinstance(state, Mapping):
        raise ValueError(f'{source}: expected a checkpoint dict (a state '
                         'dict or dict(state_dict=...)), got '
                         f'{type(loaded).__name__}')
    state = {re.sub(r'^module\.', '', k): v for k, v in state.items()}
    if prefix:
        kept = {k[len(prefix):]: v for k, v in state.items()
                if k.startswith(prefix)}
        if not kept:
            raise ValueError(
                f'checkpoint {source} has no key starting with {prefix!r}; '
                f'its keys start like {sorted(state)[:10]}')
        state = kept
    return state


def _matches(key: str, patterns: Sequence) -> bool:
    return any(re.search(p, key) for p in patterns)


def _counter(key: str) -> bool:
    """BatchNorm's ``num_batches_tracked``: a counter, not a weight (files
    of torchvision omit it; mmengine accepts its absence)."""
    return key.endswith('num_batches_tracked')


def compare_state_dicts(own: Mapping[str, Any],
                        theirs: Mapping[str, Any],
                        ignore: Sequence = (),
                        allow_missing: Sequence = ()
                        ) -> Tuple[Dict[str, Any], Dict[str, list]]:
    """Split a checkpoint's entries into what loads and what differs.

    Args:
        own (Mapping): The module's ``state_dict()``.
        theirs (Mapping): The checkpoint's state dict.
        ignore (Sequence): Patterns (str or compiled) of keys not to load
            or miss. Defaults to ().
        allow_missing (Sequence): Patterns of module keys the file may
            lack. Defaults to ().

    Returns:
        tuple: The entries to load, and lists of keys by
        :data:`REPORT_KEYS`: ``ignored`` (checkpoint keys matching
        ``ignore``), ``allowed_missing``, ``unexpected``, ``missing`` and
        ``shape`` (tuples ``(key, checkpoint shape, module shape)``).
        Counters (``num_batches_tracked``) are never reported.
    """
    report = {key: [] for key in REPORT_KEYS}
    load = {}
    for key, value in theirs.items():
        if _matches(key, ignore):
            report['ignored'].append(key)
        elif key not in own:
            if not _counter(key):
                report['unexpected'].append(key)
        elif (hasattr(value, 'shape')
              and tuple(value.shape) != tuple(own[key].shape)):
            report['shape'].append(
                (key, tuple(value.shape), tuple(own[key].shape)))
        else:
            load[key] = value
    for key in own:
        if key in theirs or _counter(key) or _matches(key, ignore):
            continue
        kind = 'allowed_missing' if _matches(key,
                                             allow_missing) else 'missing'
        report[kind].append(key)
    return load, report


def key_examples(items: List[str], count: int = 3) -> str:
    shown = ', '.join(items[:count])
    return shown + (f', ... ({len(items)} in all)'
                    if len(items) > count else '')


def state_dict_mismatch(own: Mapping[str, Any],
                        theirs: Mapping[str, Any]) -> List[str]:
    """How a checkpoint's state dict differs from a model's, in words.

    Args:
        own (Mapping): ``model.state_dict()``.
        theirs (Mapping): The checkpoint's state dict
            (:func:`unwrap_state_dict`).

    Returns:
        list[str]: One sentence per kind of difference (missing keys,
        unexpected keys, other shapes); empty if they match.
    """
    _, report = compare_state_dicts(own, theirs)
    missing, unexpected = report['missing'], report['unexpected']
    found = []
    if missing:
        found.append(f'{len(missing)} of the model\'s {len(own)} tensors '
                     f'are missing ({key_examples(missing)})')
    if unexpected:
        found.append(f'{len(unexpected)} keys are not the model\'s '
                     f'({key_examples(unexpected)})')
    if report['shape']:
        shapes = [f'{k} {a} vs {b}' for k, a, b in report['shape']]
        found.append(f'{len(shapes)} tensors have another shape '
                     f'(checkpoint vs model: {key_examples(shapes)})')
    return found


__all__ = [
    'REPORT_KEYS', 'compare_state_dicts', 'key_examples',
    'state_dict_mismatch', 'unwrap_state_dict'
]
