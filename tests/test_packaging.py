"""An installed wheel of this project and mmdet3d's own projects/ coexist.

mmdetection3d keeps its plugin projects in a top-level ``projects/`` folder
without ``__init__.py`` (``projects.BEVFusion.bevfusion``, ...), run from
its repository root. Our package is ``projects`` too; as a regular package
(with ``projects/__init__.py``) a normal install would win over every
namespace portion on sys.path and hide mmdet3d's projects. As a namespace
package both merge. Built offline: ``pip wheel --no-deps --no-index
--no-build-isolation`` with the setuptools already installed.
"""
import os
import os.path as osp
import shutil
import subprocess
import sys
import zipfile

import pytest

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
PACKAGES = ('occ_common', 'occ_cyl', 'sdg_occ')


#: Building and installing the wheel in a fresh venv: the end-to-end tier.
pytestmark = pytest.mark.slow


@pytest.fixture(scope='module')
def installed(tmp_path_factory):
    """The wheel built from a copy of the sources, installed with --target.

    Returns:
        tuple[str, str]: The wheel file and the install directory.
    """
    tmp = tmp_path_factory.mktemp('wheel')
    source = tmp / 'source'
    # A copy, so that the build's build/ and *.egg-info stay out of the
    # checkout (and away from its editable install).
    shutil.copytree(osp.join(ROOT, 'projects'), source / 'projects',
                    ignore=shutil.ignore_patterns('__pycache__'))
    for name in ('setup.py', 'setup.cfg', 'README.md'):
        shutil.copy(osp.join(ROOT, name), source / name)
    pip = [sys.executable, '-m', 'pip', '--disable-pip-version-check']
    run = dict(capture_output=True, text=True, check=True)
    subprocess.run(pip + ['wheel', '--no-deps', '--no-index',
                          '--no-build-isolation', '-w', str(tmp / 'dist'),
                          str(source)], **run)
    (wheel, ) = (tmp / 'dist').iterdir()
    target = tmp / 'site'
    subprocess.run(pip + ['install', '--no-deps', '--no-index', '--target',
                          str(target), str(wheel)], **run)
    return str(wheel), str(target)


def test_wheel_holds_the_three_packages_and_no_projects_init(installed):
    wheel, _ = installed
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
    tops = sorted({name.split('/')[1] for name in names
                   if name.startswith('projects/')})
    assert tops == sorted(PACKAGES)
    assert 'projects/__init__.py' not in names
    for package in PACKAGES:
        assert f'projects/{package}/__init__.py' in names
    # Every module of the checkout is in the wheel.
    ours = {osp.relpath(osp.join(folder, name), ROOT).replace(os.sep, '/')
            for folder, _, files in os.walk(osp.join(ROOT, 'projects'))
            for name in files if name.endswith('.py')}
    assert ours == {name for name in names if name.endswith('.py')}


def test_mmdet3d_projects_and_ours_import_together(installed, tmp_path):
    """A fake mmdet3d checkout (projects/BEVFusion/bevfusion/__init__.py,
    no __init__.py above it, as in mmdetection3d) before and after the
    installed wheel on sys.path: both packages import, ours from the
    wheel. The child runs with -S so that no editable install (.pth) of
    this checkout leaks in; the test environment's site-packages are added
    to its sys.path by hand.
    """
    _, target = installed
    mmdet3d_root = tmp_path / 'mmdetection3d'
    bevfusion = mmdet3d_root / 'projects' / 'BEVFusion' / 'bevfusion'
    bevfusion.mkdir(parents=True)
    (bevfusion / '__init__.py').write_text("NAME = 'BEVFusion'\n")
    site_dirs = [path for path in sys.path if path.endswith(
        ('site-packages', 'dist-packages')) and osp.isdir(path)]
    code = (
        'import sys, os\n'
        'sys.path += os.environ["OCC_SITE"].split(os.pathsep)\n'
        'import projects.BEVFusion.bevfusion as theirs\n'
        'import projects.occ_common as ours\n'
        'from projects.occ_cyl import TPVPolarFusion\n'
        'print(theirs.NAME)\n'
        'print(ours.__file__)\n'
        'print(TPVPolarFusion.__module__)\n')
    for order in ([target, str(mmdet3d_root)], [str(mmdet3d_root), target]):
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(order),
                   OCC_SITE=os.pathsep.join(site_dirs))
        proc = subprocess.run([sys.executable, '-S', '-c', code],
                              cwd=tmp_path, env=env, capture_output=True,
                              text=True)
        assert proc.returncode == 0, proc.stderr[-2000:]
        name, ours, module = proc.stdout.split()
        assert name == 'BEVFusion'
        assert ours == osp.join(target, 'projects', 'occ_common',
                                '__init__.py')
        assert module == 'projects.occ_cyl.tpv_polar_fusion'
