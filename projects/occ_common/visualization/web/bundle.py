"""The viewer's JavaScript: ``static/*.js`` bundled with three.js.

three.js and the bundler esbuild are pinned in the repository's
``package.json`` / ``package-lock.json`` and installed into its
``node_modules/`` by ``tools/misc/setup_browser.sh`` (``npm ci``; ``make
test`` runs it). esbuild bundles ``static/main.js`` with the parts of
three.js it imports into one minified script, in about 0.1 s, each time a
server starts or a page is exported, so that an edited ``static/`` file
never meets a stale bundle. The script needs no network when it runs, so
one exported HTML file carries the whole viewer.
"""
import functools
import os
import os.path as osp
import subprocess

STATIC_DIR = osp.join(osp.dirname(osp.abspath(__file__)), 'static')
#: The checkout whose ``node_modules/`` holds three.js and esbuild.
REPO_ROOT = osp.normpath(osp.join(STATIC_DIR, *[os.pardir] * 5))
#: Environment variable naming another ``node_modules`` folder.
NODE_MODULES_ENV = 'OCC_VIEWER_NODE_MODULES'
SETUP_HINT = ('run `bash tools/misc/setup_browser.sh` in the repository '
              '(it needs Node.js >= 18 and npm; see docs/visualization.md)')


class ViewerAssetsMissing(RuntimeError):
    """three.js or esbuild is not installed."""


def node_modules() -> str:
    """The ``node_modules`` folder holding three.js and esbuild.

    Returns:
        str: ``$OCC_VIEWER_NODE_MODULES`` if set, else the checkout's.

    Raises:
        ViewerAssetsMissing: If three.js or esbuild is not there, saying
            how to install them.
    """
    folder = os.environ.get(NODE_MODULES_ENV) or osp.join(
        REPO_ROOT, 'node_modules')
    for package in ('three', 'esbuild'):
        if not osp.isfile(osp.join(folder, package, 'package.json')):
            raise ViewerAssetsMissing(
                f'the 3D viewer needs {package} in {folder}: {SETUP_HINT}')
    return folder


@functools.lru_cache(maxsize=1)
def viewer_script() -> str:
    """The bundled viewer, a classic (non-module) minified script.

    Returns:
        str: JavaScript that runs the viewer of the page it is in.

    Raises:
        ViewerAssetsMissing: See :func:`node_modules`.
        RuntimeError: If esbuild fails (its message included).
    """
    folder = node_modules()
    esbuild = osp.join(folder, 'esbuild', 'bin', 'esbuild')
    command = [
        esbuild,
        osp.join(STATIC_DIR, 'main.js'), '--bundle', '--minify',
        '--format=iife', '--target=es2020', '--legal-comments=none',
        '--log-level=error'
    ]
    # NODE_PATH: three resolves from `folder` wherever the checkout is.
    env = dict(os.environ, NODE_PATH=folder)
    try:
        done = subprocess.run(command, capture_output=True, text=True,
                              env=env, timeout=120, check=False)
    except OSError as err:
        raise ViewerAssetsMissing(f'cannot run {esbuild} ({err}): '
                                  f'{SETUP_HINT}') from None
    if done.returncode != 0:
        raise RuntimeError(f'esbuild could not bundle the viewer:\n'
                           f'{done.stderr[-3000:]}')
    return done.stdout
