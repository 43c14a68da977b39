"""Checks of a config and its ``--cfg-options`` before a Runner is built.

mmengine accepts any top-level key and any override: a typo such as
``tset_dataloader`` is silently ignored (the run uses the base config's
``test_dataloader``), ``--cfg-options train_cfg.max_epochs`` (no ``=``)
crashes inside argparse with ``not enough values to unpack``, and
``train_cfg.max_epochs=two`` fails deep in the training loop. The tools
run these checks first:

* :class:`CfgOptionsAction`: every ``--cfg-options`` item is
  ``KEY=VALUE`` with a non-empty key and a parsable value.
* :func:`check_cfg_options`: an override of a value the config already
  has keeps its kind (bool, integer, number, string, list / tuple, dict);
  ``None`` on either side and new keys are not checked, but a new key
  must lie below a dict (or an existing list item). A number given for a
  string is taken as the text typed (``data_root=2024``).
* :func:`cfg_errors_exit`: the tools end on such an override as argparse
  ends on a malformed one: one line ``PROG: error: ...`` on stderr and
  exit status 2, no traceback.
* :func:`check_top_level_keys`: **the rule for unknown keys** is that a
  top-level key is an error when it is not read by mmengine's Runner or
  tools but lies within two edits (insert, delete, substitute, swap of
  neighbours; one edit for keys of up to six letters) of one that is.
  Configs keep any other key of their own (``point_cloud_range``,
  ``train_pipeline``, ...), since configs name their shared values at the
  top level by design; a real typo of a Runner key is almost always one or
  two keystrokes away from it. Keys starting with ``_`` are never checked.
* :func:`import_overridden_modules`: an override of ``custom_imports``
  is imported (``Config.fromfile`` imports only the file's own).
* :func:`check_env_cfg`: ``env_cfg`` is a closed dict (mmengine's
  ``Runner.setup_env`` reads :data:`ENV_CFG_KEYS` and ignores any other
  key, so ``cudnn_benchmak=True`` was silently dropped): every other key
  in it, or in its ``mp_cfg``, is an error.
"""
import contextlib
import inspect
import os.path as osp
import sys
from typing import Any, Dict, Iterable, Iterator, List, Mapping, Optional

from mmengine.config import DictAction

#: Top-level keys mmengine 0.10.7 and the tools read besides the
#: arguments of ``Runner.__init__``.
EXTRA_RUNNER_KEYS = frozenset({
    'custom_imports', 'runner_type', 'model_wrapper_cfg', 'compile',
    'activation_checkpointing', 'efficient_conv_bn_eval', 'sync_bn',
    'find_unused_parameters', 'gpu_ids', 'dist_params', 'tta_model',
    'tta_pipeline', 'strategy', 'work_dir', 'launcher', 'auto_scale_lr'
})


#: The keys of ``env_cfg`` mmengine 0.10.7's ``Runner.setup_env`` reads.
ENV_CFG_KEYS = frozenset(
    {'cudnn_benchmark', 'mp_cfg', 'dist_cfg', 'resource_limit'})


def runner_keys() -> frozenset:
    """Top-level keys the Runner (and the tools) read."""
    from mmengine.runner import Runner
    params = inspect.signature(Runner.__init__).parameters
    # ``cfg`` is the whole config, never a key of it.
    return frozenset(set(params) - {'self', 'cfg'}) | EXTRA_RUNNER_KEYS


def edit_distance(a: str, b: str) -> int:
    """Optimal string alignment distance (a swap of neighbours costs 1).

    Args:
        a (str): A string.
        b (str): Another string.

    Returns:
        int: The number of edits turning ``a`` into ``b``.
    """
    rows = [[0] * (len(b) + 1) for _ in range(len(a) + 1)]
    for i in range(len(a) + 1):
        rows[i][0] = i
    for j in range(len(b) + 1):
        rows[0][j] = j
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            cost = int(a[i - 1] != b[j - 1])
            rows[i][j] = min(rows[i - 1][j] + 1, rows[i][j - 1] + 1,
                             rows[i - 1][j - 1] + cost)
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] \
                    and a[i - 2] == b[j - 1]:
                rows[i][j] = min(rows[i][j], rows[i - 2][j - 2] + 1)
    return rows[-1][-1]


def check_top_level_keys(keys: Iterable[str], filename: str) -> None:
    """Refuse top-level keys that are typos of Runner keys.

    Args:
        keys (Iterable[str]): The config's top-level keys.
        filename (str): The config file, for the message.

    Raises:
        ValueError: Naming each suspect key and the key it resembles.
    """
    known = runner_keys()
    suspects = {}
    for key in keys:
        if key in known or key.startswith('_'):
            continue
        close = sorted(k for k in known
                       if edit_distance(key, k) <= (1 if len(k) <= 6 else 2))
        if close:
            suspects[key] = close[0]
    if suspects:
        listed = ', '.join(f'{key!r} (did you mean {near!r}?)'
                           for key, near in sorted(suspects.items()))
        raise ValueError(
            f'{filename}: unknown top-level key {listed}. mmengine ignores '
            'such a key, so the run would silently use the base config '
            'instead. Rename it; a variable of your own must not lie '
            'within two edits of a Runner key.')


def _mp_cfg_keys() -> frozenset:
    """Arguments ``env_cfg.mp_cfg`` may give ``set_multi_processing``."""
    from mmengine.utils.dl_utils import set_multi_processing
    params = inspect.signature(set_multi_processing).parameters
    return frozenset(params) - {'distributed'}  # the Runner passes it


def _unknown(keys: Iterable[str], known: frozenset) -> List[str]:
    found = []
    for key in sorted(keys):
        if key in known:
            continue
        close = sorted(k for k in known if edit_distance(key, k) <= 2)
        found.append(f'{key!r}' +
                     (f' (did you mean {close[0]!r}?)' if close else ''))
    return found


def check_env_cfg(cfg: Mapping, filename: str) -> None:
    """Refuse unknown keys in ``env_cfg`` and its ``mp_cfg``.

    Args:
        cfg (Mapping): The config.
        filename (str): The config file (or option), for the message.

    Raises:
        ValueError: Naming each unknown key and the key it resembles.
    """
    env_cfg = cfg.get('env_cfg')
    if not isinstance(env_cfg, Mapping):
        return
    problems = []
    unknown = _unknown(env_cfg, ENV_CFG_KEYS)
    if unknown:
        problems.append(f'env_cfg: {", ".join(unknown)} (it takes '
                        f'{sorted(ENV_CFG_KEYS)})')
    mp_cfg = env_cfg.get('mp_cfg')
    if isinstance(mp_cfg, Mapping):
        unknown = _unknown(mp_cfg, _mp_cfg_keys())
        if unknown:
            problems.append(f'env_cfg.mp_cfg: {", ".join(unknown)} (it '
                            f'takes {sorted(_mp_cfg_keys())})')
    if problems:
        raise ValueError(
            f'{filename}: unknown key in {"; ".join(problems)}. mmengine '
            'ignores such a key, so the run would silently go without the '
            'setting.')


class CfgOptionsError(ValueError):
    """A ``--cfg-options`` item the config cannot take."""


class CfgOptionsAction(DictAction):
    """``--cfg-options`` parser that names a malformed item.

    Records the raw text of each value in ``namespace.<dest>_raw``.
    """

    def __call__(self, parser, namespace, values, option_string=None):
        """Parse ``KEY=VALUE`` items (see ``mmengine.config.DictAction``)."""
        raw = dict(getattr(namespace, f'{self.dest}_raw', None) or {})
        for item in values or ():
            key, sep, val = item.partition('=')
            if not sep or not key:
                parser.error(f'{option_string}: expected KEY=VALUE, got '
                             f'{item!r}')
            try:
                self._parse_iterable(val)
            except (AssertionError, ValueError) as err:
                parser.error(f'{option_string}: cannot parse the value of '
                             f'{item!r} ({err})')
            raw[key] = val.strip('\'"')
        super().__call__(parser, namespace, values, option_string)
        setattr(namespace, f'{self.dest}_raw', raw)


_MISSING = object()


def _lookup(cfg: Mapping, key: str) -> Any:
    """The value at dotted ``key`` (list items by index), or _MISSING."""
    node: Any = cfg
    for part in key.split('.'):
        if isinstance(node, (list, tuple)) and part.isdigit() \
                and int(part) < len(node):
            node = node[int(part)]
        elif hasattr(node, 'keys') and part in node:  # Config, ConfigDict
            node = node[part]
        else:
            return _MISSING
    return node


def _kind(value: Any) -> Optional[str]:
    """The kind an override must keep, or None (no check)."""
    if isinstance(value, bool):
        return 'bool'
    if isinstance(value, int):
        return 'integer'
    if isinstance(value, float):
        return 'number'
    if isinstance(value, str):
        return 'string'
    if isinstance(value, (list, tuple)):
        return 'list'
    if isinstance(value, Mapping):
        return 'dict'
    return None


def _fits(kind: str, value: Any) -> bool:
    if kind == 'number':
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return _kind(value) == kind


#: Longest ``repr`` of a replaced value quoted in a message; a longer one
#: (a model's dict) is named by its kind alone, keeping the message to a
#: line.
MAX_QUOTED = 40


def _article(kind: str) -> str:
    """``'a string'``, ``'an integer'``."""
    return f'an {kind}' if kind[0] in 'aeiou' else f'a {kind}'


def _described(kind: str, value: Any) -> str:
    """``'the integer 2'``, or ``'a dict'`` when its repr is long."""
    text = repr(value)
    if len(text) > MAX_QUOTED or '\n' in text:
        return _article(kind)
    return f'the {kind} {text}'


def _parent_error(cfg: Mapping, key: str) -> Optional[str]:
    """Why ``key`` cannot be set below its parents, or None.

    mmengine merges ``a.b.c=1`` into ``a.b`` only when ``a.b`` is a dict
    (or a list indexed by ``c``); anything else fails inside the merge
    with a ``TypeError`` or ``IndexError``.
    """
    parts = key.split('.')
    node: Any = cfg
    for depth, part in enumerate(parts[:-1]):
        if isinstance(node, (list, tuple)):
            if not part.isdigit() or int(part) >= len(node):
                where = '.'.join(parts[:depth])
                items = 'item' if len(node) == 1 else 'items'
                return (f'{where} is a list of {len(node)} {items}, which '
                        f'has no item {part!r}')
            node = node[int(part)]
        elif hasattr(node, 'keys'):
            if part not in node:
                return None  # a new branch: mmengine creates it
            node = node[part]
        else:
            break
        if not (hasattr(node, 'keys') or isinstance(node, (list, tuple))):
            where = '.'.join(parts[:depth + 1])
            kind = _kind(node) or type(node).__name__
            return (f'the config has {_described(kind, node)} at {where}, '
                    'not a dict to set a key in')
    return None


def check_cfg_options(cfg: Mapping,
                      options: Dict[str, Any],
                      raw: Optional[Dict[str, str]] = None) -> Dict:
    """Check that overrides keep the kind of the values they replace.

    Args:
        cfg (Mapping): The config before the overrides.
        options (dict): Parsed ``--cfg-options``.
        raw (dict, optional): The typed text of each value
            (:class:`CfgOptionsAction`).

    Returns:
        dict: ``options``, with numbers given for strings as typed.

    Raises:
        CfgOptionsError: A ``ValueError`` naming each override of the
            wrong kind, or below a value that is not a dict.
    """
    raw = raw or {}
    checked, errors = dict(options), []
    for key, value in options.items():
        given = f'{key}={raw.get(key, value)!r}'
        parent = _parent_error(cfg, key)
        if parent is not None:
            errors.append(f'{given}, but {parent}')
            continue
        old = _lookup(cfg, key)
        kind = None if old is _MISSING or old is None else _kind(old)
        if kind is None or value is None or _fits(kind, value):
            continue
        if kind == 'string' and _kind(value) in ('bool', 'integer',
                                                 'number'):
            checked[key] = raw.get(key, str(value))
            continue
        errors.append(f'{given} ({_article(_kind(value) or "value")}), but '
                      f'the config has {_described(kind, old)} there')
    if errors:
        raise CfgOptionsError('--cfg-options of the wrong kind: ' +
                              '; '.join(errors))
    return checked


@contextlib.contextmanager
def cfg_errors_exit(prog: Optional[str] = None) -> Iterator[None]:
    """End a tool on a :class:`CfgOptionsError` as argparse ends on a bad
    argument: ``PROG: error: MESSAGE`` on one line of stderr, status 2.

    Args:
        prog (str, optional): The program's name. Defaults to the running
            script's file name.

    Yields:
        None: The tool's work runs in the ``with`` block.

    Raises:
        SystemExit: With code 2, on a ``CfgOptionsError``.
    """
    try:
        yield
    except CfgOptionsError as err:
        prog = prog or osp.basename(sys.argv[0] or 'tool')
        message = ' '.join(str(err).split())  # one line, whatever it held
        sys.stderr.write(f'{prog}: error: {message}\n')
        raise SystemExit(2) from None


def merge_cfg_options(cfg,
                      options: Dict[str, Any],
                      raw: Optional[Dict[str, str]] = None,
                      option: str = '--cfg-options') -> List[str]:
    """Check overrides (:func:`check_cfg_options`), merge them into
    ``cfg`` and check the top level they leave.

    Args:
        cfg (mmengine.Config): The loaded config, changed in place.
        options (dict): Parsed overrides (``DictAction``).
        raw (dict, optional): The typed text of each value
            (:class:`CfgOptionsAction`).
        option (str): The command-line option, for the messages.
            Defaults to '--cfg-options'.

    Returns:
        list[str]: The overridden keys.

    Raises:
        CfgOptionsError: A ``ValueError``, if an override has the wrong
            kind, cannot be merged, or adds a top-level typo.
    """
    if not options:
        return []
    options = check_cfg_options(cfg, options, raw)
    try:
        cfg.merge_from_dict(options)
    except (TypeError, KeyError, IndexError, AssertionError) as err:
        # What the checks above do not foresee still ends in one line.
        raise CfgOptionsError(f'{option}: cannot merge {sorted(options)} '
                              f'into the config ({err})') from err
    try:
        check_top_level_keys(cfg.keys(), option)
        check_env_cfg(cfg, option)
    except ValueError as err:
        raise CfgOptionsError(str(err)) from err
    import_overridden_modules(cfg, options, option)
    return sorted(options)


def import_overridden_modules(cfg, options: Dict[str, Any],
                              option: str = '--cfg-options') -> None:
    """Import ``custom_imports`` when an override changed it.

    ``Config.fromfile`` imports a config's ``custom_imports`` while it
    reads the file; an override merged afterwards was never imported, so
    ``--cfg-options custom_imports.imports=[my.module]`` silently left the
    module (and the registry entries it adds) out.

    Args:
        cfg (mmengine.Config): The config with the overrides merged.
        options (dict): The overrides.
        option (str): The command-line option, for the message.

    Raises:
        CfgOptionsError: If ``custom_imports`` is not
            ``dict(imports=[...], ...)`` or a module fails to import.
    """
    if not any(key == 'custom_imports' or key.startswith('custom_imports.')
               for key in options):
        return
    from mmengine.utils import import_modules_from_strings
    imports = cfg.get('custom_imports')
    if not isinstance(imports, Mapping) or 'imports' not in imports:
        raise CfgOptionsError(
            f'{option}: custom_imports must be dict(imports=[MODULE, ...]'
            f', allow_failed_imports=False), got {imports!r:.80}')
    try:
        import_modules_from_strings(**imports)
    except (ImportError, TypeError) as err:
        raise CfgOptionsError(f'{option}: custom_imports: {err}') from err


def apply_cfg_options(cfg, args, dest: str = 'cfg_options') -> List[str]:
    """Check and merge ``args.<dest>`` into ``cfg``; check the top level.

    Args:
        cfg (mmengine.Config): The loaded config.
        args (argparse.Namespace): Parsed with :class:`CfgOptionsAction`.
        dest (str): The option's attribute. Defaults to 'cfg_options'.

    Returns:
        list[str]: The overridden keys.

    Raises:
        ValueError: If the config has a top-level typo (see
            :func:`check_top_level_keys`) or an unknown ``env_cfg`` key
            (:func:`check_env_cfg`).
        CfgOptionsError: A ``ValueError``, if an override has the wrong
            kind, cannot be merged, or adds a top-level typo.
    """
    check_top_level_keys(cfg.keys(), cfg.filename or '<config>')
    check_env_cfg(cfg, cfg.filename or '<config>')
    return merge_cfg_options(cfg, getattr(args, dest, None),
                             getattr(args, f'{dest}_raw', None),
                             f'--{dest.replace("_", "-")}')


__all__ = [
    'CfgOptionsAction', 'CfgOptionsError', 'apply_cfg_options',
    'cfg_errors_exit', 'check_cfg_options', 'check_env_cfg',
    'check_top_level_keys', 'edit_distance', 'import_overridden_modules',
    'merge_cfg_options', 'runner_keys'
]
