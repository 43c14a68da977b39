"""tools/misc/env_check.py: what the setup keeps, installs or refuses.

The decisions take the installed versions as arguments, so made-up
environments stand in for a user's CUDA machine (no GPU here); the last
tests run the command line against this environment itself.
"""
import importlib.util
import os.path as osp
import subprocess
import sys

import pytest

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
TOOL = osp.join(ROOT, 'tools', 'misc', 'env_check.py')


def _tool():
    """tools/misc/env_check.py as a module."""
    spec = importlib.util.spec_from_file_location('env_check_tool', TOOL)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


env_check = _tool()


@pytest.mark.parametrize('version', [(3, 9, 18), (3, 10, 0), (3, 11, 7),
                                     (3, 12, 1)])
def test_supported_pythons(version):
    assert env_check.check_python(version) == 'Python {}.{}'.format(
        *version[:2])


@pytest.mark.parametrize('version', [(3, 8, 18), (3, 13, 0), (2, 7, 18)])
def test_unsupported_python_says_which(version):
    with pytest.raises(env_check.EnvError, match='CPython 3.9 to 3.12'):
        env_check.check_python(version)


def test_torch_missing_is_installed():
    decision, notes = env_check.torch_decision(None)
    assert decision == 'install' and 'pinned' in notes[0]


def test_cuda_torch_is_kept():
    decision, notes = env_check.torch_decision('2.1.2+cu121', cuda='12.1')
    assert decision == 'keep'
    assert notes == ['keeping installed torch 2.1.2+cu121 (cuda 12.1)']


def test_torch_newer_than_tested_is_kept_with_a_note():
    decision, notes = env_check.torch_decision('2.15.0', cuda='13.0')
    assert decision == 'keep' and 'newer than 2.13' in notes[1]


@pytest.mark.parametrize('version', ['1.13.1+cu117', '2.0.0rc1'])
def test_torch_1_is_refused(version):
    """2.0.0rc1 < 2.0.0 in PEP 440 order, so a pre-release is refused."""
    with pytest.raises(env_check.EnvError, match='older than 2.0.0'):
        env_check.torch_decision(version)


def test_fitting_mmcv_with_ops_is_kept():
    decision, notes = env_check.mmcv_decision(
        '2.1.0', None, '2.1.2+cu121', cuda='12.1', ops_cuda='12.1')
    assert (decision, notes) == ('keep', ['keeping installed mmcv 2.1.0'])


def test_mmcv_range_bounds():
    """[2.0.0rc4, 2.2.0): rc4 is in, 2.2.0 and rc3 are out."""
    keep = env_check.mmcv_decision('2.0.0rc4', None, '2.13.0+cpu')
    assert keep[0] == 'keep'
    for version in ('2.2.0', '2.0.0rc3'):
        decision, notes = env_check.mmcv_decision(version, None, '2.13.0')
        assert decision == 'build' and 'outside' in notes[0]


def test_cpu_torch_gets_mmcv_built():
    decision, notes = env_check.mmcv_decision(None, None, '2.13.0+cpu')
    assert decision == 'build'
    assert 'built against torch 2.13.0+cpu' in notes[0]


def test_mmcv_without_ops_is_rebuilt_on_cpu():
    decision, notes = env_check.mmcv_decision(
        '2.1.0', 'ImportError: undefined symbol', '2.13.0+cpu')
    assert decision == 'build' and 'compiled ops do not load' in notes[0]


def test_cuda_env_without_mmcv_gets_the_prebuilt_wheel_command():
    """torch 2.1.2+cu121 -> OpenMMLab's cu121/torch2.1 index."""
    with pytest.raises(env_check.EnvError) as error:
        env_check.mmcv_decision(None, None, '2.1.2+cu121', cuda='12.1')
    assert ('pip install mmcv==2.1.0 -f https://download.openmmlab.com/mmcv/'
            'dist/cu121/torch2.1/index.html') in str(error.value)


def test_cuda_env_with_mmcv_2_2_is_refused_not_replaced():
    with pytest.raises(env_check.EnvError, match=r'mmcv 2.2.0 is outside'):
        env_check.mmcv_decision('2.2.0', None, '2.0.1+cu118', cuda='11.8')


def test_cuda_torch_newer_than_prebuilt_wheels_says_build():
    with pytest.raises(env_check.EnvError, match='no mmcv 2.1.0 wheel for '
                       'torch 2.4.*OCC_BUILD_MMCV=1'):
        env_check.mmcv_decision(None, None, '2.4.1+cu124', cuda='12.4')


def test_occ_build_mmcv_allows_a_cuda_source_build():
    decision, _ = env_check.mmcv_decision(None, None, '2.4.1+cu124',
                                          cuda='12.4', allow_build=True)
    assert decision == 'build'


def test_cpu_mmcv_under_cuda_torch_is_kept_with_a_warning():
    decision, notes = env_check.mmcv_decision(
        '2.1.0', None, '2.1.0+cu118', cuda='11.8', ops_cuda='not available')
    assert decision == 'keep'
    assert notes[1].startswith('warning: torch is a CUDA build but mmcv')


@pytest.mark.parametrize('name', ['spconv-cu121', 'spconv_cu118',
                                  'Spconv-CU120'])
def test_cuda_spconv_is_kept(name):
    """Any spelling of a spconv-cuXXX distribution counts."""
    installed = {'torch': '2.1.2+cu121', name: '2.3.6', 'cumm-cu121': '0.4.11'}
    decision, notes = env_check.spconv_decision(installed, cuda='12.1')
    assert decision == 'keep'
    assert 'CPU spconv is not installed over it' in notes[0]


def test_cpu_spconv_or_none_gets_the_pin():
    assert env_check.spconv_decision({'spconv': '2.3.8'}) == ('install', [])
    assert env_check.spconv_decision({'numpy': '1.26.4'}) == ('install', [])


def test_cuda_torch_without_cuda_spconv_warns():
    decision, notes = env_check.spconv_decision({}, cuda='12.1')
    assert decision == 'install'
    assert 'pip install spconv-cu121' in notes[0]


def test_two_spconv_distributions_are_refused():
    with pytest.raises(env_check.EnvError) as error:
        env_check.spconv_decision({'spconv': '2.3.8', 'spconv-cu121': '2.3.6'})
    assert 'spconv 2.3.8, spconv-cu121 2.3.6' in str(error.value)


def test_old_cuda_spconv_is_refused():
    with pytest.raises(env_check.EnvError, match=r'spconv-cu113 2.1.25 is '
                       r'outside the supported \[2.3.0, 3.0.0\)'):
        env_check.spconv_decision({'spconv-cu113': '2.1.25'})


def test_unrelated_spconv_prefixed_names_are_ignored():
    """Only spconv and spconv-cuNNN provide the module."""
    installed = {'spconv-plus': '1.0', 'cumm-cu121': '0.4.11'}
    assert env_check.spconv_decision(installed) == ('install', [])


def _run(what):
    return subprocess.run([sys.executable, TOOL, what], capture_output=True,
                          text=True, cwd=ROOT)


def test_cli_on_this_environment():
    """The environment that runs the tests is a supported one: its torch and
    mmcv are kept, and its spconv distribution is the CPU one or a CUDA one.
    """
    assert _run('python').stdout == 'ok\n'
    assert _run('torch').stdout == 'keep\n'
    assert _run('mmcv').stdout == 'keep\n'
    spconv = _run('spconv')
    assert spconv.returncode == 0
    names = [name for name in env_check.installed_distributions()
             if env_check.SPCONV_DIST.match(name)]
    expected = 'keep' if names and names != ['spconv'] else 'install'
    assert spconv.stdout == expected + '\n'


def test_cli_refusal_exits_2_with_the_message():
    """An interpreter the setup refuses: run the tool under a fake
    sys.version_info through -c, as setup_env.sh would see it."""
    code = ('import runpy, sys; sys.version_info = (3, 8, 18); '
            f'sys.argv = [{TOOL!r}, "python"]; '
            f'runpy.run_path({TOOL!r}, run_name="__main__")')
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True,
                          text=True)
    assert proc.returncode == 2 and proc.stdout == ''
    assert proc.stderr.startswith('[setup] error: Python 3.8 is not '
                                  'supported')


def test_versions_compare_without_packaging_installed():
    """The setup decides before installing anything, so a bare venv
    (pip only) must do: pip's vendored packaging stands in."""
    code = ('import sys; sys.modules["packaging"] = None; '
            'import importlib.util as u; '
            f's = u.spec_from_file_location("t", {TOOL!r}); '
            'm = u.module_from_spec(s); s.loader.exec_module(m); '
            'print(m.mmcv_decision("2.2.0", None, "2.13.0")[0], '
            'm._version("2.0.0rc4") < m._version("2.0.0"))')
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == 'build True\n'
