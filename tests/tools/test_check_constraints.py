"""requirements/constraints.txt pins each package once on Python 3.9-3.12.

Offline halves of tools/misc/check_constraints.py (its ``--resolve`` half asks
the package index and is run by hand; see docs/get_started.md).
"""
import importlib.metadata
import importlib.util
import os.path as osp
import re

import pytest
from packaging.specifiers import SpecifierSet
from packaging.utils import canonicalize_name

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
REQ = osp.join(ROOT, 'requirements')


def _tool():
    """tools/misc/check_constraints.py as a module."""
    spec = importlib.util.spec_from_file_location(
        'check_constraints_tool',
        osp.join(ROOT, 'tools', 'misc', 'check_constraints.py'))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


check = _tool()
PINS = check.read_pins(osp.join(REQ, 'constraints.txt'))


def _write(tmp_path, text):
    path = tmp_path / 'constraints.txt'
    path.write_text(text)
    return check.read_pins(str(path))


def test_every_package_has_one_pin_per_python():
    assert check.coverage_problems(PINS, ('3.9', '3.10', '3.11', '3.12')) \
        == []


def test_markers_pick_the_version_per_python(tmp_path):
    pins = _write(tmp_path, (
        '# comment\n'
        'pandas==2.3.3; python_version < "3.11"\n'
        'pandas==3.0.6; python_version >= "3.11"\n'
        'numpy==1.26.4\n'))
    assert check.pins_for(pins, '3.9') == {'pandas': '2.3.3',
                                           'numpy': '1.26.4'}
    assert check.pins_for(pins, '3.10') == {'pandas': '2.3.3',
                                            'numpy': '1.26.4'}
    assert check.pins_for(pins, '3.11') == {'pandas': '3.0.6',
                                            'numpy': '1.26.4'}


def test_a_gap_and_an_overlap_are_reported(tmp_path):
    pins = _write(tmp_path, (
        'scipy==1.13.1; python_version < "3.10"\n'
        'scipy==1.17.1; python_version >= "3.11"\n'
        'Pillow==11.3.0; python_version < "3.12"\n'
        'pillow==13.0.0; python_version >= "3.11"\n'))
    problems = check.coverage_problems(pins, ('3.9', '3.10', '3.11'))
    assert problems == ['scipy has no pin for Python 3.10',
                        'pillow is pinned twice for Python 3.11 (lines 3 '
                        'and 4)']


def test_a_line_that_is_not_a_pin_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r'constraints.txt:2: expected '
                       r'"name==version"'):
        _write(tmp_path, 'numpy==1.26.4\nscipy>=1.13\n')


def test_requirements_are_all_pinned():
    """Every package named in runtime.txt and tests.txt has a pin."""
    pinned = {pin[0] for pin in PINS}
    for name in ('runtime.txt', 'tests.txt'):
        with open(osp.join(REQ, name)) as file:
            for line in file:
                line = line.split('#')[0].strip()
                if line:
                    package = re.match(r'[A-Za-z0-9._-]+', line).group()
                    assert canonicalize_name(package) in pinned, (name, line)


def test_unmarked_pins_install_on_every_supported_python():
    """An installed package pinned without a marker must accept 3.9-3.12
    (its Requires-Python); one pinned for ``>= "3.11"`` must accept 3.11
    and 3.12. The old file pinned pandas 3.0.6 (Requires-Python >= 3.11)
    for every Python. Pins whose version is not the installed one (not
    this Python's) are not checked here; check_constraints.py --resolve
    checks them against the index.
    """
    checked = 0
    for name, version, marker, number in PINS:
        try:
            dist = importlib.metadata.distribution(name)
        except importlib.metadata.PackageNotFoundError:
            continue
        if dist.version != version:
            continue
        if marker is None:
            pythons = ('3.9', '3.10', '3.11', '3.12')
        else:
            pythons = [python for python in ('3.9', '3.10', '3.11', '3.12')
                       if marker.evaluate({'python_version': python})]
        requires = SpecifierSet(dist.metadata['Requires-Python'] or '')
        refused = [python for python in pythons
                   if not requires.contains(python + '.0')]
        assert not refused, (
            f'constraints.txt:{number}: {name}=={version} requires Python '
            f'{requires}, but the line applies to {refused}')
        checked += 1
    assert checked > 40  # most of the stack is installed here


def test_unpinned_names_what_the_constraints_leave_free():
    would = ['Would install numpy-1.26.4 nvidia-cublas-cu12-12.8.4.1 '
             'triton-3.4.0 cuda-toolkit-13.0.3.0 setuptools-80.9.0 '
             'some_new-pkg-0.1']
    assert check.unpinned(would, PINS, '3.11') == ['some-new-pkg']
