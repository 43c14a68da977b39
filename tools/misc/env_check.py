"""The supported stack, and what ``tools/misc/setup_env.sh`` keeps or
installs.

Every range the setup enforces lives here, once, next to the reason for
it; docs/get_started.md's "Supported versions" table states the same
ranges. The setup script runs one subcommand per decision under the
environment's own
interpreter, which prints one word (``keep`` / ``install`` / ``build``)
on stdout and explains itself on stderr; an unsupported environment exits
with status 2 and a message that says what to change::

    python tools/misc/env_check.py python    # the interpreter itself
    python tools/misc/env_check.py torch     # keep | install
    python tools/misc/env_check.py mmcv      # keep | build
    python tools/misc/env_check.py spconv    # keep | install

The decisions are pure functions of what is installed, so tests feed them
made-up environments (a CUDA torch, two spconv distributions, ...).
Only the standard library is imported at module level: the ``python``
check runs before the environment exists, under any Python 3.
"""
import argparse
import os
import re
import sys

# numpy 1.26.4 (the pinned stack) has wheels for CPython 3.9-3.12 only.
SUPPORTED_PYTHON = ((3, 9), (3, 12))
# mmcv 2.1.0 and mmdet3d 1.4 are built for torch 2.x; OpenMMLab's prebuilt
# mmcv 2.1.0 wheels cover torch 2.0 and 2.1. The CPU stack is tested on
# TESTED_TORCH; newer releases are kept, with a note.
MIN_TORCH = '2.0.0'
TESTED_TORCH = '2.13'
# mmdet3d 1.4 asserts mmcv >= 2.0.0rc4, < 2.2.0 at import.
MMCV_RANGE = ('2.0.0rc4', '2.2.0')
MMCV_PIN = '2.1.0'
# The sparse backend uses spconv 2.x's ConvAlgo, SparseConvolutionBase and
# cppconstants.CPU_ONLY_BUILD, all present from 2.3 on.
SPCONV_RANGE = ('2.3.0', '3.0.0')
# CUDA builds of spconv are separate distributions (spconv-cu118,
# spconv-cu121, ...) that install the same ``spconv`` module as the CPU one.
SPCONV_DIST = re.compile(r'^spconv(-cu\d+)?$')
# OpenMMLab's prebuilt mmcv 2.1.0 wheels exist for these torch minors.
MMCV_PREBUILT_TORCH = ('2.0', '2.1')


class EnvError(RuntimeError):
    """The environment is outside the supported stack; says what to do."""


def _version(text):
    """``packaging.version.Version`` of ``text``.

    Imported lazily, and from pip's vendored copy where ``packaging`` is
    not installed: the setup decides before it installs anything.
    """
    try:
        from packaging.version import Version
    except ImportError:
        from pip._vendor.packaging.version import Version
    return Version(text)


def _in_range(version, low, high):
    """Whether ``low <= version < high`` (PEP 440 order)."""
    return _version(low) <= _version(version) < _version(high)


def normalize(name):
    """PEP 503 normalised distribution name (``Spconv_CU121`` ->
    ``spconv-cu121``)."""
    return re.sub(r'[-_.]+', '-', name).lower()


def check_python(version_info):
    """Refuse an interpreter outside :data:`SUPPORTED_PYTHON`.

    Args:
        version_info (tuple): ``sys.version_info`` or a made-up
            ``(major, minor, ...)``.

    Returns:
        str: A one-line description of the accepted interpreter.
    """
    low, high = SUPPORTED_PYTHON
    current = tuple(version_info[:2])
    if not low <= current <= high:
        raise EnvError(
            'Python {}.{} is not supported: the pinned stack (numpy 1.26.4, '
            'mmcv 2.1.0, mmdet3d 1.4) needs CPython {}.{} to {}.{}. Run the '
            'setup with PYTHON=python3.X (a supported one) or point VENV at '
            'an environment that has one.'.format(*current, *low, *high))
    return 'Python {}.{}'.format(*current)


def torch_build(cuda, hip=None):
    """Name a torch build: ``'cpu'``, ``'cuda 12.1'`` or ``'rocm 5.6'``."""
    if cuda:
        return 'cuda ' + cuda
    if hip:
        return 'rocm ' + hip
    return 'cpu'


def torch_decision(version, cuda=None, hip=None):
    """Keep an installed torch that fits, install one where none is.

    Args:
        version (str | None): ``torch.__version__``; None if absent.
        cuda (str | None): ``torch.version.cuda``.
        hip (str | None): ``torch.version.hip``.

    Returns:
        tuple[str, list[str]]: ``'keep'`` or ``'install'``, and notes.
    """
    if version is None:
        return 'install', ['no torch installed: installing the pinned one '
                           '(requirements/constraints.txt)']
    if _version(version) < _version(MIN_TORCH):
        raise EnvError(
            'torch {} is older than {}, the oldest this library supports '
            '(mmcv 2.1.0 and mmdet3d 1.4 need torch 2.x). Install torch '
            '2.0 or newer (with CUDA, 2.0 or 2.1 match OpenMMLab\'s prebuilt '
            'mmcv 2.1.0 wheels) and run the setup again.'.format(
                version, MIN_TORCH))
    notes = ['keeping installed torch {} ({})'.format(
        version, torch_build(cuda, hip))]
    release = _version(version).release[:2]
    if release > _version(TESTED_TORCH).release[:2]:
        notes.append('note: torch {} is newer than {}, the newest version '
                     'this stack is tested with'.format(version, TESTED_TORCH))
    return 'keep', notes


def mmcv_wheel_hint(torch_version, cuda):
    """How to get a CUDA mmcv 2.1.0 for this torch, in one sentence."""
    minor = '.'.join(str(part) for part in _version(torch_version).release[:2])
    if cuda and minor in MMCV_PREBUILT_TORCH:
        index = ('https://download.openmmlab.com/mmcv/dist/cu{}/torch{}/'
                 'index.html'.format(cuda.replace('.', ''), minor))
        return ('install OpenMMLab\'s prebuilt wheel: pip install mmcv=={} '
                '-f {} (or: mim install mmcv=={})'.format(
                    MMCV_PIN, index, MMCV_PIN))
    return ('OpenMMLab publishes no mmcv {} wheel for torch {}; build it '
            'from source with the CUDA toolkit: MMCV_WITH_OPS=1 FORCE_CUDA=1 '
            'pip install --no-build-isolation mmcv=={} (about 20-40 '
            'minutes), or rerun this setup with OCC_BUILD_MMCV=1'.format(
                MMCV_PIN, minor, MMCV_PIN))


def mmcv_decision(mmcv_version, ops_error, torch_version, cuda=None,
                  ops_cuda=None, allow_build=False):
    """Keep a fitting mmcv, build the pinned one in CPU environments.

    A CUDA environment never gets a source build unasked: it would take
    tens of minutes, needs the CUDA toolkit, and would replace whatever
    the user installed; the error says which wheel to install instead.

    Args:
        mmcv_version (str | None): ``mmcv.__version__``; None if absent.
        ops_error (str | None): Why ``mmcv`` or ``mmcv.ops`` failed to
            import; None when its compiled ops load.
        torch_version (str): ``torch.__version__``.
        cuda (str | None): ``torch.version.cuda``.
        ops_cuda (str | None): ``mmcv.ops.get_compiling_cuda_version()``;
            ``'not available'`` for a build without CUDA kernels.
        allow_build (bool): ``OCC_BUILD_MMCV=1``: build from source even
            with a CUDA torch. Defaults to False.

    Returns:
        tuple[str, list[str]]: ``'keep'`` or ``'build'``, and notes.
    """
    low, high = MMCV_RANGE
    if mmcv_version is None:
        problem = 'mmcv is not installed'
    elif not _in_range(mmcv_version, low, high):
        problem = ('mmcv {} is outside [{}, {}), which mmdet3d 1.4 '
                   'requires'.format(mmcv_version, low, high))
    elif ops_error is not None:
        problem = ('mmcv {} is installed but it or its compiled ops do not '
                   'load ({}): mmcv-lite, a build for another torch, or a '
                   'missing dependency'.format(mmcv_version, ops_error))
    else:
        notes = ['keeping installed mmcv {}'.format(mmcv_version)]
        if cuda and ops_cuda == 'not available':
            notes.append(
                'warning: torch is a CUDA build but mmcv\'s ops were compiled '
                'without CUDA: mmdet3d modules that call mmcv.ops on GPU '
                'will fail; ' + mmcv_wheel_hint(torch_version, cuda))
        return 'keep', notes
    if cuda and not allow_build:
        raise EnvError('{}. torch {} is a CUDA build, so the setup does not '
                       'build mmcv itself; {}.'.format(
                           problem, torch_version,
                           mmcv_wheel_hint(torch_version, cuda)))
    return 'build', ['{}: installing mmcv {} built against torch {}'.format(
        problem, MMCV_PIN, torch_version)]


def spconv_decision(distributions, cuda=None):
    """Keep a CUDA spconv; never install the CPU wheel over it.

    ``spconv`` (CPU) and ``spconv-cuXXX`` are different distributions of
    one import name: installing the pinned CPU ``spconv`` next to a CUDA
    one overwrites its files, after which the sparse layers silently run
    the pure-torch backend on CUDA.

    Args:
        distributions (dict[str, str]): Installed distribution name ->
            version (any spelling; see :func:`installed_distributions`).
        cuda (str | None): ``torch.version.cuda`` (for the CPU-wheel
            warning).

    Returns:
        tuple[str, list[str]]: ``'keep'`` (leave spconv out of the
        install) or ``'install'`` (the pinned CPU ``spconv``), and notes.
    """
    found = {normalize(name): version
             for name, version in distributions.items()
             if SPCONV_DIST.match(normalize(name))}
    if len(found) > 1:
        listed = ', '.join('{} {}'.format(name, version)
                           for name, version in sorted(found.items()))
        names = sorted(found) + [name.replace('spconv', 'cumm', 1)
                                 for name in sorted(found)]
        raise EnvError(
            'several spconv distributions are installed ({}); they all '
            'provide the module `spconv` (and their cumm builds the module '
            '`cumm`), so the last one installed overwrote the others. Run '
            'pip uninstall -y {}, then install the one matching your torch '
            '(spconv-cuXXX for CUDA XX.X, spconv for CPU only) and run the '
            'setup again.'.format(listed, ' '.join(names)))
    cuda_builds = [name for name in found if name != 'spconv']
    if cuda_builds:
        name = cuda_builds[0]
        low, high = SPCONV_RANGE
        if not _in_range(found[name], low, high):
            raise EnvError(
                '{} {} is outside the supported [{}, {}); install {}>={}'
                .format(name, found[name], low, high, name, low))
        return 'keep', ['keeping installed {} {} (CUDA build; the CPU '
                        'spconv is not installed over it)'.format(
                            name, found[name])]
    notes = []
    if cuda:
        notes.append(
            'warning: torch is a CUDA {} build but no spconv-cu* is '
            'installed: the CPU spconv is installed, and sparse layers on '
            'CUDA run the pure-torch backend. For the fused kernels: pip '
            'uninstall spconv && pip install spconv-cu{}'.format(
                cuda, cuda.replace('.', '')))
    return 'install', notes


def installed_distributions():
    """Installed distributions of the running interpreter.

    Returns:
        dict[str, str]: Normalised name -> version.
    """
    import importlib.metadata  # Python >= 3.8; see check_python
    found = {}
    for dist in importlib.metadata.distributions():
        name = dist.metadata['Name']
        if name:
            found[normalize(name)] = dist.version
    return found


def _installed_torch():
    """(version, cuda, hip) of the importable torch, or Nones."""
    try:
        import torch
    except ImportError:
        return None, None, None
    return (torch.__version__, torch.version.cuda,
            getattr(torch.version, 'hip', None))


def _installed_mmcv():
    """(version, ops import error, ops CUDA version) of mmcv, or Nones."""
    import importlib.metadata
    try:
        version = importlib.metadata.version('mmcv')
    except importlib.metadata.PackageNotFoundError:
        return None, None, None
    try:
        import mmcv  # noqa: F401
        from mmcv.ops import get_compiling_cuda_version, nms  # noqa: F401
    except Exception as error:  # ImportError, OSError: undefined symbol
        return version, '{}: {}'.format(type(error).__name__, error), None
    return version, None, get_compiling_cuda_version()


def _decide(args):
    """Run one subcommand against the running interpreter."""
    if args.what == 'python':
        return 'ok', [check_python(sys.version_info)]
    torch_version, cuda, hip = _installed_torch()
    if args.what == 'torch':
        return torch_decision(torch_version, cuda, hip)
    if args.what == 'mmcv':
        if torch_version is None:
            raise EnvError('torch must be installed before mmcv')
        mmcv_version, ops_error, ops_cuda = _installed_mmcv()
        return mmcv_decision(
            mmcv_version, ops_error, torch_version, cuda, ops_cuda=ops_cuda,
            allow_build=os.environ.get('OCC_BUILD_MMCV') == '1')
    return spconv_decision(installed_distributions(), cuda)


def main(argv=None):
    """Print the decision on stdout, notes on stderr; 2 if unsupported."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('what', choices=('python', 'torch', 'mmcv', 'spconv'))
    args = parser.parse_args(argv)
    try:
        decision, notes = _decide(args)
    except EnvError as error:
        print('[setup] error: {}'.format(error), file=sys.stderr)
        return 2
    for note in notes:
        print('[setup] ' + note, file=sys.stderr)
    print(decision)
    return 0


if __name__ == '__main__':
    sys.exit(main())
