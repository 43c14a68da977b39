"""Names taken from files (tokens, scene and camera names) are checked by
the one helper, ``fileio.safe_names.safe_file_name``, before they name a
file: a token of ``../x`` wrote outside the demo's temporary folder."""
import ast
import os
import os.path as osp
import re

import pytest

from projects.occ_common.datasets.single_sample import sample_info_file
from projects.occ_common.fileio.safe_names import safe_file_name
from projects.occ_common.fileio.safe_pickle import load_info_file
from projects.occ_common.testing.mmdet3d_infos import write_mmdet3d_info_file
from projects.occ_common.testing.tool_logs import REPO_ROOT


@pytest.mark.parametrize('name', [
    'ca9a282c9e77460f8360f564131a8af5', 'scene-0061', 'CAM_FRONT',
    'n015-2018-07-24-11-22-45+0800__LIDAR_TOP__1532402927647951.pcd.bin',
    '0', 'a' * 200
])
def test_names_of_nuscenes_pass_unchanged(name):
    assert safe_file_name(name, 'x') == name


@pytest.mark.parametrize('name', [
    '', '.', '..', '../x', 'a/b', '/tmp/x', 'a\\b', '.hidden', '-rf',
    'a b', 'a\x00b', 'é', 'a' * 201
])
def test_other_names_are_refused_naming_value_and_source(name):
    with pytest.raises(ValueError, match='infos.pkl: sample token') as err:
        safe_file_name(name, 'sample token', 'infos.pkl')
    assert repr(name[:80]) in str(err.value)


# -- every path built from a token, scene or camera name is checked ------

#: Identifiers that hold a name taken from a file.
_NAME = re.compile(r'token|scene|cam', re.I)
#: An f-string ending so names a file.
_SUFFIX = re.compile(r'\.(png|npz|npy|pkl|json|bin|jpe?g|pth|txt|onnx)$')
#: The checks: a value they return may name a file.
_CHECKS = {'safe_file_name', 'sample_name'}
#: Sites whose names do not come from a file, and why.
_ALLOWED = {
    ('projects/occ_common/synthetic/scene_writer.py', 'write_key_frame'):
    'the generator makes the token itself (make_token)',
    ('projects/occ_common/datasets/converters/extend_mmdet3d_infos.py',
     '_occ3d_index'):
    'folder names listed from the disk, not read from a file',
    ('projects/occ_common/analysis/fault_cases_inputs.py', '_sample'):
    'the fault matrix names the files of the info file it makes itself',
}


def _called(node) -> str:
    func = node.func
    return func.id if isinstance(func, ast.Name) else getattr(
        func, 'attr', '')


def _identifier(node):
    """The name an expression reads (``token``, ``info['token']``)."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    if isinstance(node, ast.Subscript):
        key = node.slice
        if isinstance(key, ast.Constant) and isinstance(key.value, str):
            return key.value
        return _identifier(node.value)
    return None


def _path_parts(node):
    """Expressions that become part of a path at ``node``: the arguments
    after the first of ``osp.join`` / ``os.path.join``, and the fields of
    an f-string ending in a file suffix."""
    if isinstance(node, ast.Call) and _called(node) == 'join' and \
            isinstance(node.func, ast.Attribute) and \
            ast.unparse(node.func.value) in ('osp', 'os.path'):
        for arg in node.args[1:]:
            if isinstance(arg, ast.JoinedStr):
                yield from (v.value for v in arg.values
                            if isinstance(v, ast.FormattedValue))
            else:
                yield arg
    elif isinstance(node, ast.JoinedStr) and node.values and isinstance(
            node.values[-1], ast.Constant) and _SUFFIX.search(
                str(node.values[-1].value)):
        yield from (v.value for v in node.values
                    if isinstance(v, ast.FormattedValue))


def unchecked_name_paths(source: str):
    """``(function, line, expression)`` of each path part that reads a
    token, scene or camera name not returned by one of :data:`_CHECKS`
    in the same function (each once)."""
    seen = set()
    for func in ast.walk(ast.parse(source)):
        if not isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        checked = {
            target.id
            for node in ast.walk(func) if isinstance(node, ast.Assign)
            and isinstance(node.value, ast.Call)
            and _called(node.value) in _CHECKS
            for target in node.targets if isinstance(target, ast.Name)
        }
        for node in ast.walk(func):
            for part in _path_parts(node):
                if isinstance(part, ast.Call):
                    if _called(part) in _CHECKS | {'basename'}:
                        continue
                    if _called(part) == 'str' and part.args:
                        part = part.args[0]
                name = _identifier(part)
                site = (func.name, part.lineno, ast.unparse(part))
                if name and _NAME.search(name) and not (
                        isinstance(part, ast.Name) and part.id in checked
                ) and site not in seen:
                    seen.add(site)
                    yield site


def _library_files():
    for top in ('projects', 'tools', 'demo'):
        for folder, _, names in os.walk(osp.join(REPO_ROOT, top)):
            if 'testing' in folder.split(os.sep):
                continue  # helpers of the tests
            for name in sorted(names):
                if name.endswith('.py'):
                    yield osp.join(folder, name)


def test_every_path_built_from_a_name_of_a_file_is_checked():
    """Scans projects/, tools/ and demo/ for path parts that read a
    ``token`` / ``scene`` / ``cam`` name: each must be the value of
    ``safe_file_name`` (or ``sample_name``, which calls it) in its
    function. Seven writers and readers do today (the demo, the
    single-sample conversion, the prediction files, the visualisation
    hook's pictures, the Occ3D label lookup of the converter, the
    synthetic world's files, benchmark_data.py's stand-in root)."""
    found = []
    for path in _library_files():
        rel = osp.relpath(path, REPO_ROOT)
        with open(path) as f:
            for func, line, expr in unchecked_name_paths(f.read()):
                if (rel, func) not in _ALLOWED:
                    found.append(f'{rel}:{line} {func}: {expr}')
    assert not found, ('paths built from names read from files, without '
                       'fileio.safe_names.safe_file_name:\n' +
                       '\n'.join(found))


def test_the_scan_finds_an_unchecked_writer():
    """The scan itself: a new writer without the check is found, one
    with it is not."""
    bad = ("def write(out, info):\n"
           "    return osp.join(out, f'{info[\"token\"]}.png')\n")
    good = ("def write(out, info):\n"
            "    token = safe_file_name(info['token'], 'token')\n"
            "    return osp.join(out, f'{token}.png')\n")
    assert list(unchecked_name_paths(bad)) == [
        ('write', 2, "info['token']")]
    assert list(unchecked_name_paths(good)) == []


# -- the demo's single-sample conversion ----------------------------------


@pytest.mark.parametrize('token', ['../victim', '/ABS'])
def test_token_of_an_mmdet3d_sample_writes_nothing_outside(
        converted_tiny_world, tmp_path, token):
    """demo/occ_demo.py and export_onnx.py --verify convert a sample of an
    mmdet3d info file into ``<tmp>/<token>_info.pkl``. A token of
    ``../victim`` overwrote ``victim_info.pkl`` beside the temporary
    folder (and ``/ABS`` created ``/ABS_info.pkl``'s folder at the root);
    now it is refused before anything is written."""
    entry = load_info_file(osp.join(
        converted_tiny_world,
        'nuscenes_occ_infos_train.pkl'))['data_list'][0]
    entry['token'] = token.replace('/ABS', str(tmp_path / 'abs'))
    info_file = write_mmdet3d_info_file(str(tmp_path / 'infos.pkl'),
                                        [entry])
    victim = tmp_path / 'victim_info.pkl'
    victim.write_text('keep me')
    out_dir = tmp_path / 'tmp'
    with pytest.raises(ValueError, match=r'infos\.pkl: sample token'):
        sample_info_file(info_file, converted_tiny_world, str(out_dir))
    assert victim.read_text() == 'keep me'
    assert sorted(os.listdir(tmp_path)) == ['infos.pkl', 'victim_info.pkl']
