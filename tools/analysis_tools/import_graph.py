"""Import cycles and imports running up the floors of the library.

The library is built in floors: a module may import its own floor and the
floors below it, never one above. ``projects/occ_common`` from the bottom:

==========  ==========================================================
floor       packages
==========  ==========================================================
 0          ``utils`` (runtime primitives)
 1          ``fileio``
 2          ``geometry``
 3          ``datasets``
 4          ``transforms``
 5          ``models``; the model modules of ``occ_cyl`` and ``sdg_occ``
 6          ``evaluation``
 7          ``visualization``
 8          ``synthetic``
 9          ``engine``
10          ``apis``
11          ``analysis``
12          ``deployment``; ``occ_cyl.deployment``, ``sdg_occ.deployment``
13          ``testing`` (helpers of the tests; no library module, tool or
            demo imports it)
==========  ==========================================================

The package ``__init__`` files of ``projects.occ_common``, ``occ_cyl`` and
``sdg_occ`` only gather registrations and sit above every floor.

Usage::

    python tools/analysis_tools/import_graph.py [--root .]

prints every module-level cycle, upward import and import of
``testing`` from outside it, and exits 1 if there is any.
"""
import argparse
import ast
import os
import os.path as osp
import sys
from typing import Dict, List, Optional, Set, Tuple

COMMON = 'projects.occ_common'
#: ``projects.occ_common``'s packages, bottom floor first.
FLOORS = ('utils', 'fileio', 'geometry', 'datasets', 'transforms', 'models',
          'evaluation', 'visualization', 'synthetic', 'engine', 'apis',
          'analysis', 'deployment', 'testing')
MODEL_PROJECTS = ('projects.occ_cyl', 'projects.sdg_occ')
TOP = len(FLOORS)


def floor(module: str) -> Optional[int]:
    """The floor of a library module, None outside the layered packages.

    Args:
        module (str): Dotted module name, e.g.
            ``'projects.occ_common.fileio.safe_pickle'``.

    Returns:
        int, optional: Its index in :data:`FLOORS`; :data:`TOP` for the
        projects' own ``__init__`` files; None for a module that is not
        part of ``projects``.
    """
    parts = module.split('.')
    if module == COMMON or module in MODEL_PROJECTS:
        return TOP
    if module.startswith(COMMON + '.'):
        return FLOORS.index(parts[2]) if parts[2] in FLOORS else None
    for project in MODEL_PROJECTS:
        if module.startswith(project + '.'):
            deployment = parts[2] == 'deployment'
            return FLOORS.index('deployment' if deployment else 'models')
    return None


def python_modules(root: str, top: str) -> Dict[str, str]:
    """Every module under ``root/top`` by dotted name (packages by their
    ``__init__``)."""
    found = {}
    for folder, dirs, files in os.walk(osp.join(root, top)):
        dirs[:] = sorted(d for d in dirs if d != '__pycache__')
        for name in sorted(files):
            if name.endswith('.py'):
                path = osp.join(folder, name)
                module = osp.relpath(path, root)[:-3].replace(os.sep, '.')
                found[module.rsplit('.__init__', 1)[0]] = path
    return found


def imports_of(path: str, module: str, known: Set[str]) -> Set[str]:
    """The library modules a file imports, at any depth of its code.

    ``from P import x`` counts as an import of ``P.x`` where that is a
    module, else of ``P``; relative imports are resolved first.
    """
    tree = ast.parse(open(path, encoding='utf-8').read(), path)
    package = module if path.endswith('__init__.py') else module.rsplit(
        '.', 1)[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name in known)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                parts = package.split('.')
                parts = parts[:len(parts) - node.level + 1]
                base = '.'.join(parts + ([node.module] if node.module else []))
            for alias in node.names:
                if f'{base}.{alias.name}' in known:
                    found.add(f'{base}.{alias.name}')
                elif base in known:
                    found.add(base)
    found.discard(module)
    return found


def cycles(graph: Dict[str, Set[str]]) -> List[List[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    sys.setrecursionlimit(max(10000, sys.getrecursionlimit()))
    for node in sorted(graph):
        if node not in index:
            visit(node)
    return out


def analyse(root: str) -> Tuple[List[List[str]], List[str], List[str]]:
    """Cycles, upward imports and imports of ``testing`` under ``root``.

    Args:
        root (str): The repository root.

    Returns:
        tuple: ``(cycles, upward, testing)``: lists of module cycles, of
        ``'a -> b (floor i -> j)'`` lines and of ``'file -> module'``
        lines for imports of ``projects.occ_common.testing`` from the
        library (outside ``testing``), ``tools/`` or ``demo/``.
    """
    library = python_modules(root, 'projects')
    graph = {m: imports_of(p, m, set(library)) for m, p in library.items()}
    upward = []
    for module, targets in sorted(graph.items()):
        low = floor(module)
        for target in sorted(targets):
            high = floor(target)
            if low is not None and high is not None and high > low:
                upward.append(f'{module} -> {target} (floor {low} -> {high})')
    helpers = f'{COMMON}.testing'
    testing = [
        f'{module} -> {target}' for module, targets in sorted(graph.items())
        if not module.startswith(helpers) for target in sorted(targets)
        if target == helpers or target.startswith(helpers + '.')
    ]
    for top in ('tools', 'demo'):
        for module, path in python_modules(root, top).items():
            for target in sorted(imports_of(path, module, set(library))):
                if target.startswith(helpers):
                    testing.append(f'{osp.relpath(path, root)} -> {target}')
    return cycles(graph), upward, testing


def main(argv=None) -> int:
    """Print the findings; 1 if there is any."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--root', default=osp.dirname(osp.dirname(
        osp.dirname(osp.abspath(__file__)))), help='repository root')
    args = parser.parse_args(argv)
    found_cycles, upward, testing = analyse(args.root)
    for component in found_cycles:
        print('cycle: ' + ' <-> '.join(component))
    for line in upward:
        print('upward: ' + line)
    for line in testing:
        print('imports a test helper: ' + line)
    print(f'{len(found_cycles)} cycles, {len(upward)} upward imports, '
          f'{len(testing)} imports of test helpers')
    return 1 if found_cycles or upward or testing else 0


if __name__ == '__main__':
    sys.exit(main())
