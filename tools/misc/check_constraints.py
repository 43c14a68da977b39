"""Prove that the pinned requirements resolve on every supported Python.

``requirements/constraints.txt`` pins each package once per Python, with
environment markers where one version does not cover CPython 3.9-3.12
(pandas 3, scipy 1.17, matplotlib 3.11 need 3.11). Offline, this checks
that every package has exactly one pin for each Python (the unit test
does the same). With ``--resolve`` it asks pip, for each Python, without
installing anything (``pythonX -m pip install --dry-run
--only-binary=:all: --target TMP``, that Python's own pip, since pip's
``--python-version`` evaluates dependency markers such as pytest's
``exceptiongroup; python_version < "3.11"`` for the host Python):

1. that every pin for that Python exists as a wheel for it (``--no-deps``);
2. that build, runtime and test requirements plus torch resolve together
   under the constraints, as ``tools/misc/setup_env.sh`` installs them;
3. that the ``--no-deps`` OpenMMLab packages install on it.

This needs the package index (the network), so it is a check script, not
a test::

    .venv/bin/python tools/misc/check_constraints.py --resolve [--python 3.9]
"""
import argparse
import glob
import os.path as osp
import re
import shutil
import subprocess
import sys
import tempfile

from packaging.markers import Marker
from packaging.utils import canonicalize_name

ROOT = osp.dirname(
    osp.dirname(osp.dirname(osp.abspath(__file__))))
REQ = osp.join(ROOT, 'requirements')
PYTHONS = ('3.9', '3.10', '3.11', '3.12')
PIN = re.compile(r'^(?P<name>[A-Za-z0-9][A-Za-z0-9._-]*)==(?P<version>\S+?)'
                 r'\s*(;\s*(?P<marker>.+))?$')


def read_pins(path):
    """Parse a constraints file of ``name==version[; marker]`` lines.

    Args:
        path (str): The constraints file.

    Returns:
        list[tuple[str, str, Marker | None, int]]: Canonical name, version,
        marker and line number of each pin.
    """
    pins = []
    with open(path) as file:
        for number, line in enumerate(file, 1):
            line = line.strip()
            if not line or line.startswith('#'):
                continue
            match = PIN.match(line)
            if match is None:
                raise ValueError(
                    f'{path}:{number}: expected "name==version" with an '
                    f'optional "; marker", got {line!r}')
            marker = match['marker']
            pins.append((canonicalize_name(match['name']), match['version'],
                         Marker(marker) if marker else None, number))
    return pins


def pins_for(pins, python):
    """The pins that apply on one Python version.

    Args:
        pins (list): As returned by :func:`read_pins`.
        python (str): ``'3.9'`` etc.

    Returns:
        dict[str, str]: Canonical name -> version.
    """
    env = {'python_version': python, 'python_full_version': python + '.0'}
    chosen, lines = {}, {}
    for name, version, marker, number in pins:
        if marker is not None and not marker.evaluate(env):
            continue
        if name in chosen:
            raise ValueError(
                f'{name} is pinned twice for Python {python} (lines '
                f'{lines[name]} and {number})')
        chosen[name], lines[name] = version, number
    return chosen


def coverage_problems(pins, pythons=PYTHONS):
    """Packages that lack a pin, or have two, on one of ``pythons``.

    Args:
        pins (list): As returned by :func:`read_pins`.
        pythons (tuple[str]): Python versions. Defaults to 3.9-3.12.

    Returns:
        list[str]: One line per problem; empty when every package has
        exactly one pin on every Python.
    """
    names = sorted({pin[0] for pin in pins})
    problems = []
    for python in pythons:
        try:
            chosen = pins_for(pins, python)
        except ValueError as error:
            problems.append(str(error))
            continue
        problems += [f'{name} has no pin for Python {python}'
                     for name in names if name not in chosen]
    return problems


def find_interpreter(python):
    """A CPython of version ``python`` on PATH or under pyenv, or None."""
    names = [f'python{python}'] + sorted(glob.glob(osp.expanduser(
        f'~/.pyenv/versions/{python}.*/bin/python{python}')))
    for name in names:
        path = shutil.which(name) or (name if osp.isfile(name) else None)
        if path is None:
            continue
        probe = subprocess.run(
            [path, '-c', 'import sys; print("%d.%d" % sys.version_info[:2])'],
            capture_output=True, text=True)
        if probe.returncode == 0 and probe.stdout.strip() == python:
            return path
    return None


def unpinned(would_install, pins, python):
    """Packages pip would install that the constraints leave free.

    torch's own CUDA runtime (``nvidia-*``, ``triton``, ``cuda-*``) is
    left out: torch's metadata pins it exactly. So is build.txt, which pins
    its own.

    Args:
        would_install (list[str]): pip's ``Would install a-1.0 b-2`` lines.
        pins (list): As returned by :func:`read_pins`.
        python (str): The Python the pins are for.

    Returns:
        list[str]: Canonical names, sorted.
    """
    pinned = set(pins_for(pins, python))
    pinned |= {pin[0] for pin in read_pins(osp.join(REQ, 'build.txt'))}
    free = set()
    for line in would_install:
        for item in line.split()[2:]:
            name = canonicalize_name(item.rsplit('-', 1)[0])
            if name not in pinned and not name.startswith(
                    ('nvidia-', 'cuda-')) and name != 'triton':
                free.add(name)
    return sorted(free)


def _pip(pip, args, target):
    """``pip install --dry-run`` into an empty target; installs nothing.

    Returns:
        tuple[bool, list[str]]: Whether pip succeeded, and what it would
        install (on success) or its last lines (on failure).
    """
    cmd = pip + ['install', '--dry-run', '--ignore-installed',
                 '--only-binary=:all:', '--target', target] + args
    proc = subprocess.run(cmd, capture_output=True, text=True)
    out = (proc.stdout + proc.stderr).strip().splitlines()
    if proc.returncode == 0:
        return True, [line for line in out
                      if line.startswith('Would install')]
    return False, [line for line in out if 'is ignored' not in line][-8:]


def resolve(python, pins, interpreter=None, host_pip=None):
    """Run the three pip checks of the module docstring for one Python.

    Args:
        python (str): ``'3.9'`` etc.
        pins (list): As returned by :func:`read_pins`.
        interpreter (str | None): That Python's executable; its own pip
            resolves, so every marker (ours and the dependencies') is
            evaluated for it.
        host_pip (list[str] | None): Without an interpreter, this pip
            with ``--python-version``: it checks Requires-Python and wheel
            tags for ``python`` but evaluates dependency markers for the
            host, so the result is approximate.

    Returns:
        list[tuple[str, bool, list[str]]]: (check, passed, pip's output)
        for each check.
    """
    if interpreter is not None:
        pip = [interpreter, '-m', 'pip']
    else:
        pip = host_pip + ['--python-version', python]
    req = [f'{name}=={version}'
           for name, version in sorted(pins_for(pins, python).items())]
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        pinned = osp.join(tmp, 'pins.txt')
        with open(pinned, 'w') as file:
            file.write('\n'.join(req) + '\n')
        target = osp.join(tmp, 'target')
        results.append((f'{len(req)} pins exist',) + _pip(
            pip, ['--no-deps', '-r', pinned], target))
        # The constraints as pip would read them on `python`: our markers
        # are already evaluated, so the host's version cannot leak in.
        passed, out = _pip(pip, ['-c', pinned, 'torch',
                                 '-r', osp.join(REQ, 'build.txt'),
                                 '-r', osp.join(REQ, 'runtime.txt'),
                                 '-r', osp.join(REQ, 'tests.txt')], target)
        results.append(('build + runtime + tests + torch resolve', passed,
                        out))
        if passed:
            free = unpinned(out, pins, python)
            results.append(('every resolved package is pinned', not free,
                            [f'unpinned: {", ".join(free)}'] if free else []))
        results.append(('openmmlab.txt (--no-deps)',) + _pip(
            pip, ['--no-deps', '-r', osp.join(REQ, 'openmmlab.txt')],
            target))
    return results


def main(argv=None):
    """Check coverage; with --resolve, ask pip; exit 1 on any failure."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--python', action='append', choices=PYTHONS,
                        help='check only this Python (repeatable)')
    parser.add_argument('--resolve', action='store_true',
                        help='ask pip (needs the package index)')
    parser.add_argument('--pip', default=f'{sys.executable} -m pip',
                        help='pip (>= 22.2) for a Python with no '
                        'interpreter here (approximate, see resolve())')
    args = parser.parse_args(argv)
    pythons = tuple(args.python or PYTHONS)
    pins = read_pins(osp.join(REQ, 'constraints.txt'))
    problems = coverage_problems(pins, pythons)
    for problem in problems:
        print(f'coverage: {problem}')
    failed = bool(problems)
    if not problems:
        print(f'coverage: every package has one pin on Python '
              f'{", ".join(pythons)}')
    if args.resolve:
        for python in pythons:
            interpreter = find_interpreter(python)
            print(f'Python {python}: '
                  f'{interpreter or "no interpreter: approximate check"}')
            for check, passed, tail in resolve(python, pins, interpreter,
                                               args.pip.split()):
                print(f'Python {python}: {check}: '
                      f'{"ok" if passed else "FAILED"}')
                for line in tail:
                    print('    ' + line)
                failed = failed or not passed
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
