"""Import hygiene of the plugin sources, read from the files themselves.

* Importing a package registers its modules and does nothing else: no
  module of ``projects/`` imports a plotting library when it is imported
  (the visualisation imports matplotlib when it draws). mmengine and
  mmdet3d import matplotlib themselves, so this is checked on our sources
  rather than on ``sys.modules``.
* No import circle, not even one hidden behind ``TYPE_CHECKING``.
"""
import ast
import glob
import os.path as osp

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
DEFERRED = ('matplotlib', )


def _imports(path, module_level=True):
    """Modules imported at module level (or anywhere), relative ones
    resolved against the file's package."""
    with open(path) as f:
        tree = ast.parse(f.read(), path)
    package = osp.relpath(osp.dirname(path), ROOT).replace(osp.sep, '.')
    names = []
    nodes = tree.body if module_level else ast.walk(tree)
    for node in nodes:
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit('.', node.level - 1)[0] if node.level > 1 \
                else package
            if node.level == 0:
                names.append(node.module)
            else:
                names += [f'{base}.{node.module}'] if node.module else [
                    f'{base}.{alias.name}' for alias in node.names
                ]
    return names


def test_no_module_imports_matplotlib_at_import_time():
    """Every deferred library is imported inside the function that uses
    it (occ_figure imports matplotlib in _legend and _compose)."""
    found = []
    for path in glob.glob(osp.join(ROOT, 'projects', '**', '*.py'),
                          recursive=True):
        for name in _imports(path):
            if name.split('.')[0] in DEFERRED:
                found.append(f'{osp.relpath(path, ROOT)}: {name}')
    assert found == []


def test_no_import_circle_in_the_sparse_package():
    """Within models/sparse, the modules (any import, TYPE_CHECKING ones
    included) form an acyclic graph: the backends depend on the layer
    protocol in backend.py, not on sparse_conv.py, which imports them."""
    package = 'projects.occ_common.models.sparse'
    folder = osp.join(ROOT, *package.split('.'))
    graph = {}
    for path in glob.glob(osp.join(folder, '*.py')):
        name = osp.splitext(osp.basename(path))[0]
        if name == '__init__':
            continue
        graph[name] = {
            dep[len(package) + 1:].split('.')[0]
            for dep in _imports(path, module_level=False)
            if dep.startswith(package + '.')
        }
    done, active = set(), []

    def visit(node):
        assert node not in active, ' -> '.join(active + [node])
        if node in done:
            return
        active.append(node)
        for dep in sorted(graph.get(node, ())):
            visit(dep)
        active.pop()
        done.add(node)

    for node in sorted(graph):
        visit(node)
    assert {'sparse_conv', 'torch_backend', 'spconv_backend'} <= done
