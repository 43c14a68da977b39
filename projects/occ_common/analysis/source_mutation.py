"""One-line regressions of a function, made in this process only.

The fault matrix's mutation check
(``tools/analysis_tools/fault_matrix.py --mutations``) asks, for every
guard of the library, whether some case notices when that guard's line is
broken. :func:`mutate` recompiles one function (or method) from its
source with one line replaced and puts the new function where the old one
was: on its class or module, and in every loaded module that imported it
by name. Nothing on disk changes; the matrix mutates in the forked child
that runs the case.
"""
import importlib
import inspect
import sys
import textwrap
from typing import Any, Tuple


class MutationError(ValueError):
    """The mutation's text is not (exactly once) in its function."""


def _owner_and_name(target: str) -> Tuple[Any, str, Any]:
    """``(owner, attribute, function)`` of ``'module:Qual.name'``."""
    module_name, qualname = target.split(':')
    owner = importlib.import_module(module_name)
    parts = qualname.split('.')
    for part in parts[:-1]:
        owner = getattr(owner, part)
    return owner, parts[-1], inspect.getattr_static(owner, parts[-1])


def mutated_source(target: str, old: str, new: str) -> str:
    """The source of ``target`` with ``old`` replaced by ``new``.

    Args:
        target (str): ``'package.module:function'`` or
            ``'package.module:Class.method'``.
        old (str): Text found exactly once in its source.
        new (str): Its replacement.

    Returns:
        str: The changed, dedented source.

    Raises:
        MutationError: If ``old`` is not found exactly once (the guard's
            code changed: update the mutation).
    """
    function = _owner_and_name(target)[2]
    source = textwrap.dedent(inspect.getsource(inspect.unwrap(function)))
    if source.count(old) != 1:
        raise MutationError(f'{target}: {old!r} is in its source '
                            f'{source.count(old)} times, not once')
    return source.replace(old, new)


def mutate(target: str, old: str, new: str) -> None:
    """Replace ``target`` by its source with ``old`` -> ``new``.

    The function is compiled in its module's globals inside a function
    holding its class as ``__class__``, so that a method's ``super()``
    still works.

    Args:
        target (str): See :func:`mutated_source`.
        old (str): See :func:`mutated_source`.
        new (str): See :func:`mutated_source`.

    Raises:
        MutationError: See :func:`mutated_source`.
    """
    owner, name, function = _owner_and_name(target)
    module = sys.modules[target.split(':')[0]]
    source = mutated_source(target, old, new)
    wrapper = ('def __mutation(__class__):\n' +
               textwrap.indent(source, '    ') + f'\n    return {name}\n')
    namespace: dict = {}
    exec(compile(wrapper, f'<mutation of {target}>', 'exec'),
         module.__dict__, namespace)
    made = namespace['__mutation'](owner if inspect.isclass(owner) else None)
    setattr(owner, name, made)
    if not inspect.isclass(owner):
        for loaded in list(sys.modules.values()):
            space = getattr(loaded, '__dict__', None)
            if isinstance(space, dict) and space.get(name) is function:
                setattr(loaded, name, made)


__all__ = ['MutationError', 'mutate', 'mutated_source']
