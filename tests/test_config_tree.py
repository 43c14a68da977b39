"""The config tree stays shallow and small.

A reader must find every value of a config within three files: the config
and at most two generations of ``_base_`` files, as in mmdet3d, whose own
configs are 2-3 levels deep. A deeper chain hides where a value comes from
and lets two files state the same fact. The whole tree is also held under a
line budget, so that a new config reuses what the bases state instead of
restating it.

Depth counts files along the longest chain: ``a.py`` with
``_base_ = ['b.py']`` and ``b.py`` with ``_base_ = ['c.py']`` is 3 files
deep, a config without ``_base_`` is 1; e.g. the SDG-KL config
``sdgocc-kl_r50_4xb2-24e_occ3d-nus.py`` -> its SDG-Fusion config -> any of
the flat bases that one lists (``_base_/sdgocc-fusion_r50.py``, ...) is 3.
The ``_base_`` lists are read from the syntax tree: no config is executed
and no model built, so this runs in well under a second.
"""
import ast
import functools
import glob
import os.path as osp

import pytest

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
CONFIGS = sorted(
    glob.glob(osp.join(ROOT, 'configs', '**', '*.py'), recursive=True))
MAX_DEPTH = 3  # files: the config plus two generations of _base_ files
# All config .py files together: 1,500 lines, the budget since the tree
# was flattened on 2026-11-28.
MAX_LINES = 1500


def _bases(path):
    """The files a config's ``_base_`` names, as absolute paths."""
    with open(path, encoding='utf-8') as f:
        tree = ast.parse(f.read(), filename=path)
    for node in tree.body:
        if (isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == '_base_'
                for t in node.targets)):
            value = ast.literal_eval(node.value)
            names = [value] if isinstance(value, str) else list(value)
            return [
                osp.normpath(osp.join(osp.dirname(path), n)) for n in names
            ]
    return []


@functools.lru_cache(maxsize=None)
def _chain(path):
    """The longest chain of files from ``path`` through ``_base_``."""
    longest = []
    for base in _bases(path):
        assert osp.isfile(base), f'{path} names a missing base {base}'
        chain = _chain(base)
        if len(chain) > len(longest):
            longest = chain
    return (path, ) + tuple(longest)


def test_chain_counts_files():
    """A base-less config is one file deep; the example in the module
    docstring is three."""
    assert CONFIGS, 'no configs found'
    roots = [p for p in CONFIGS if not _bases(p)]
    assert roots and all(len(_chain(p)) == 1 for p in roots)
    kl = osp.join(ROOT, 'configs', 'sdg_occ',
                  'sdgocc-kl_r50_4xb2-24e_occ3d-nus.py')
    chain = _chain(kl)
    assert len(chain) == 3 and osp.basename(chain[1]) == (
        'sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py')
    fusion_bases = _bases(chain[1])
    assert chain[2] in fusion_bases and osp.join(
        ROOT, 'configs', 'sdg_occ', '_base_',
        'sdgocc-fusion_r50.py') in fusion_bases


@pytest.mark.parametrize(
    'path', CONFIGS, ids=[osp.relpath(p, ROOT) for p in CONFIGS])
def test_inheritance_depth(path):
    chain = _chain(path)
    assert len(chain) <= MAX_DEPTH, (
        f'{len(chain)} files deep (at most {MAX_DEPTH}): ' +
        ' -> '.join(osp.relpath(p, ROOT) for p in chain))


def test_total_lines():
    total = 0
    for path in CONFIGS:
        with open(path, encoding='utf-8') as f:
            total += sum(1 for _ in f)
    assert total <= MAX_LINES, (
        f'configs/ holds {total} lines of Python (at most {MAX_LINES}): '
        'state a value once in a _base_ file and derive the rest')
