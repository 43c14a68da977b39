"""The project's code runs on Python 3.9, the oldest supported version.

CI runs 3.11, so nothing else would notice 3.10+ code. Two checks over
every ``.py`` file in projects/, tools/, configs/ and tests/: the file
parses with Python 3.9's grammar (``match``, ``except*``, ``type X``,
generic ``def f[T]`` are rejected), and no annotation that Python 3.9
would evaluate at import uses PEP 604's ``X | Y``, nor does code call
``zip(strict=...)`` (3.10) or import a 3.10+ standard-library name.
"""
import ast
import os
import os.path as osp

import pytest

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
OLDEST = (3, 9)
# Standard-library names added after 3.9 (module -> names), as imported.
NEWER_STDLIB = {
    'tomllib': None, 'itertools': {'pairwise'},
    'typing': {'TypeAlias', 'ParamSpec', 'Concatenate', 'TypeGuard', 'Self',
               'LiteralString', 'Never', 'Required', 'NotRequired',
               'Unpack', 'TypeVarTuple', 'assert_never', 'assert_type',
               'reveal_type', 'dataclass_transform', 'override'},
    'datetime': {'UTC'}, 'enum': {'StrEnum', 'verify'},
    'contextlib': {'aclosing', 'chdir'},
}


def _sources():
    for top in ('projects', 'tools', 'configs', 'tests', 'demo'):
        for folder, _, files in os.walk(osp.join(ROOT, top)):
            for name in sorted(files):
                if name.endswith('.py'):
                    yield osp.relpath(osp.join(folder, name), ROOT)


SOURCES = sorted(_sources())


def _evaluated_annotations(tree):
    """Annotations Python 3.9 evaluates at definition time: all of them,
    unless the module has ``from __future__ import annotations``."""
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module == '__future__' \
                and any(alias.name == 'annotations' for alias in node.names):
            return
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            args = node.args
            for arg in (args.posonlyargs + args.args + args.kwonlyargs
                        + [args.vararg, args.kwarg]):
                if arg is not None and arg.annotation is not None:
                    yield arg.annotation
            if node.returns is not None:
                yield node.returns
        elif isinstance(node, ast.AnnAssign):
            yield node.annotation


def problems_of(source, name='<source>'):
    """What keeps ``source`` from running on Python 3.9.

    Returns:
        list[str]: ``'name:line: problem'`` strings; empty when fine.
    """
    try:
        ast.parse(source, name, feature_version=OLDEST)
    except SyntaxError as error:
        return [f'{name}:{error.lineno}: not Python 3.9 syntax: {error.msg}']
    tree = ast.parse(source, name)
    found = []
    for annotation in _evaluated_annotations(tree):
        for node in ast.walk(annotation):
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.BitOr):
                found.append(f'{name}:{node.lineno}: X | Y annotation '
                             '(PEP 604, Python 3.10)')
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id == 'zip' \
                and any(kw.arg == 'strict' for kw in node.keywords):
            found.append(f'{name}:{node.lineno}: zip(strict=) (Python 3.10)')
        elif isinstance(node, ast.Import):
            found += [f'{name}:{node.lineno}: import {alias.name} (Python '
                      '3.11)' for alias in node.names
                      if alias.name in NEWER_STDLIB
                      and NEWER_STDLIB[alias.name] is None]
        elif isinstance(node, ast.ImportFrom) and node.module in NEWER_STDLIB:
            newer = NEWER_STDLIB[node.module]
            found += [f'{name}:{node.lineno}: {node.module}.{alias.name} '
                      '(after Python 3.9)' for alias in node.names
                      if newer is None or alias.name in newer]
    return found


@pytest.mark.parametrize('snippet, problem', [
    ('match x:\n    case 1:\n        pass\n', 'not Python 3.9 syntax'),
    ('try:\n    pass\nexcept* ValueError:\n    pass\n',
     'not Python 3.9 syntax'),
    ('def f(x: int | None) -> None:\n    pass\n', 'X | Y annotation'),
    ('def f(x) -> "int" | None:\n    pass\n', 'X | Y annotation'),
    ('y: int | str = 1\n', 'X | Y annotation'),
    ('pairs = list(zip(a, b, strict=True))\n', 'zip(strict=)'),
    ('import tomllib\n', 'import tomllib'),
    ('from typing import TypeAlias\n', 'typing.TypeAlias'),
    ('from itertools import pairwise\n', 'itertools.pairwise'),
])
def test_the_checks_catch_newer_code(snippet, problem):
    """Each check really fires (Python's ``feature_version`` is best
    effort, so the syntax ones are checked too)."""
    (found, ) = problems_of(snippet)
    assert problem in found


@pytest.mark.parametrize('snippet', [
    'from __future__ import annotations\n\ndef f(x: int | None): pass\n',
    'def f(x: "int | None"): pass\n',
    'flags = a | b\n',
    'from typing import Optional, Union\n',
    'x = [y := 1]\n',
    'name = "abc".removeprefix("a")\n',
])
def test_the_checks_accept_3_9_code(snippet):
    """Postponed or string annotations, a plain bitwise or, the walrus and
    3.9's own additions are fine."""
    assert problems_of(snippet) == []


def test_project_code_runs_on_python_3_9():
    assert len(SOURCES) > 150
    assert {'tools/misc/env_check.py', 'projects/occ_common/__init__.py',
            'tests/test_python_compat.py'} <= set(SOURCES)
    found = []
    for path in SOURCES:
        with open(osp.join(ROOT, path), encoding='utf-8') as file:
            found += problems_of(file.read(), path)
    assert found == []
