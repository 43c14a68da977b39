r"""Every pickle the project reads goes through the restricted loaders.

The rule, over ``projects/``, ``tools/`` and ``demo/``: outside the loader
module (:data:`ALLOWED`, each with its reason) nothing calls an
unpickler. Info files are read with
``projects.occ_common.fileio.load_info_file``, checkpoints with
``load_checkpoint_file`` (or mmengine's loaders once
``install_checkpoint_loader`` has run). A grep finds most of it::

    grep -rnE 'pickle\.(loads?|Unpickler)|allow_pickle' projects tools demo
    grep -rnE '(torch|jit|mmengine|fileio)\.load\(' projects tools demo

This test reads the code instead (calls only, so docstrings may name them;
``import pickle as p`` / ``from mmengine import load`` are followed).
"""
import ast
import glob
import os.path as osp
from typing import Dict, Iterator, Tuple

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))

#: Calls that unpickle (``mmengine.load`` does for ``.pkl``; for JSON or
#: YAML use ``json`` / ``yaml``).
FORBIDDEN = frozenset({
    'pickle.load', 'pickle.loads', 'pickle.Unpickler', 'pickle._Unpickler',
    '_pickle.load', '_pickle.loads', '_pickle.Unpickler', 'torch.load',
    'torch.jit.load', 'mmengine.load', 'mmengine.fileio.load',
    'mmengine.fileio.io.load', 'dill.load', 'dill.loads', 'joblib.load',
    'pandas.read_pickle'
})

#: Files that may, and why.
ALLOWED = {
    'projects/occ_common/fileio/safe_pickle.py':
    'the restricted loaders: pickle unpicklers with a restricted '
    'find_class and BUILD, torch.load with their pickle_module',
}


def _aliases(tree: ast.AST) -> Dict[str, str]:
    """Local name -> dotted name of the imports of a module."""
    names = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                local = alias.asname or alias.name.split('.')[0]
                names[local] = alias.name if alias.asname else local
        elif isinstance(node, ast.ImportFrom) and node.module:
            for alias in node.names:
                names[alias.asname or alias.name] = \
                    f'{node.module}.{alias.name}'
    return names


def _dotted(node: ast.AST, aliases: Dict[str, str]) -> str:
    """``a.b.c`` of a name or attribute chain, imports resolved."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return ''
    parts.append(aliases.get(node.id, node.id))
    return '.'.join(reversed(parts))


def _violations(path: str) -> Iterator[Tuple[int, str]]:
    """``(line, what)`` of each unpickling call of a source file."""
    with open(path, encoding='utf-8') as f:
        tree = ast.parse(f.read(), path)
    aliases = _aliases(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            name = _dotted(node.func, aliases)
            if name in FORBIDDEN:
                yield node.lineno, f'{name}(...)'
            pickled = any(
                kw.arg == 'allow_pickle' and not (
                    isinstance(kw.value, ast.Constant)
                    and kw.value.value is False) for kw in node.keywords)
            if pickled:
                yield node.lineno, f'{name}(..., allow_pickle=...)'
        elif isinstance(node, ast.ClassDef):
            for base in node.bases:
                if _dotted(base, aliases) in FORBIDDEN:
                    yield node.lineno, \
                        f'class {node.name}({_dotted(base, aliases)})'


def _sources():
    for folder in ('projects', 'tools', 'demo'):
        yield from sorted(
            glob.glob(osp.join(ROOT, folder, '**', '*.py'), recursive=True))


def test_no_pickle_is_read_outside_the_restricted_loaders():
    """Lists every offending call as ``file:line: call``."""
    found = [
        f'{osp.relpath(path, ROOT)}:{line}: {what}' for path in _sources()
        if osp.relpath(path, ROOT) not in ALLOWED
        for line, what in _violations(path)
    ]
    assert not found, (
        'pickles read outside the restricted loaders (use load_info_file / '
        'load_checkpoint_file of projects.occ_common.fileio):\n' +
        '\n'.join(found))


def test_the_rule_finds_what_it_forbids(tmp_path):
    """Each way of calling an unpickler is found; a loader's name in a
    docstring or np.load(allow_pickle=False) is not."""
    source = tmp_path / 'x.py'
    source.write_text(
        '"""torch.load(x) in a docstring."""\n'
        'import pickle as p\n'
        'import numpy as np\n'
        'import torch\n'
        'from mmengine import load\n'
        'p.loads(b"")\n'
        'torch.load("x.pth")\n'
        'load("infos.pkl")\n'
        'np.load("x.npy", allow_pickle=True)\n'
        'np.load("x.npy", allow_pickle=False)\n'
        'class U(p.Unpickler):\n'
        '    pass\n')
    assert sorted(line for line, _ in _violations(str(source))) == \
        [6, 7, 8, 9, 11]
    assert set(ALLOWED) <= {osp.relpath(p, ROOT) for p in _sources()}
