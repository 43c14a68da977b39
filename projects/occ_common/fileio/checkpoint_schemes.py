"""mmengine's checkpoint schemes, each loading through the restricted loader.

mmengine's ``CheckpointLoader`` serves every checkpoint a Runner reads
(``load_from``, ``--resume``, ``init_cfg=dict(type='Pretrained')``,
``tools/test.py``'s checkpoint) by the scheme of its name: local paths,
``http(s)://`` (torch hub's cache), ``torchvision://`` / ``modelzoo://``,
``open-mmlab://`` / ``openmmlab://``, ``mmcls://``, ``pavi://`` and
``s3://`` / ``petrel://``. Each of mmengine's own loaders ends in a plain
``torch.load``, which on torch < 2.6 unpickles anything and on every torch
runs a TorchScript archive's code. :func:`install_checkpoint_loader`
replaces every one of them by a loader here that finds the file as
mmengine does and reads it with
:func:`~.safe_pickle.load_checkpoint_file` (or
:func:`~.safe_pickle.load_checkpoint_stream` for a download in memory).
"""
import io
import os.path as osp
from tempfile import TemporaryDirectory

from .hub_cache import cached_download, torchvision_url
from .safe_pickle import load_checkpoint_file, load_checkpoint_stream


def _load_from_local(filename: str, map_location=None):
    """Scheme ``''``: a local path."""
    return load_checkpoint_file(filename, map_location)


def _load_from_http(filename: str, map_location=None, model_dir=None):
    """Scheme ``http(s)://``: into torch hub's cache as mmengine does
    (:func:`~.hub_cache.cached_download`), then as a local file."""
    return load_checkpoint_file(cached_download(filename, model_dir),
                                map_location)


def _load_from_torchvision(filename: str, map_location=None):
    """Schemes ``torchvision://NAME`` and ``modelzoo://NAME``: the URL of
    NAME (:func:`~.hub_cache.torchvision_url`), then as ``https://``."""
    return load_checkpoint_file(
        cached_download(torchvision_url(filename), name=filename),
        map_location)


def _load_from_openmmlab(filename: str, map_location=None):
    """Schemes ``open-mmlab://NAME`` / ``openmmlab://NAME``: mmengine's
    URL or file (under ``$MMENGINE_HOME``) of NAME."""
    from mmengine.runner.checkpoint import (_get_mmengine_home,
                                            get_deprecated_model_names,
                                            get_external_models)
    name = filename.split('://', 1)[1]
    name = get_deprecated_model_names().get(name, name)
    url = get_external_models()[name]
    if url.startswith(('http://', 'https://')):
        return _load_from_http(url, map_location)
    return load_checkpoint_file(
        osp.join(_get_mmengine_home(), url), map_location)


def _load_from_mmcls(filename: str, map_location=None):
    """Scheme ``mmcls://NAME``: mmengine's URL of NAME, its backbone."""
    from mmengine.runner.checkpoint import (_process_mmcls_checkpoint,
                                            get_mmcls_models)
    url = get_mmcls_models()[filename[len('mmcls://'):]]
    return _process_mmcls_checkpoint(_load_from_http(url, map_location))


def _load_from_pavi(filename: str, map_location=None):
    """Scheme ``pavi://``: downloaded with pavi, as mmengine does."""
    try:
        from pavi import modelcloud
    except ImportError:
        raise ImportError(
            'Please install pavi to load checkpoint from modelcloud.')
    model = modelcloud.get(filename[len('pavi://'):])
    with TemporaryDirectory() as folder:
        downloaded = osp.join(folder, model.name)
        model.download(downloaded)
        return load_checkpoint_file(downloaded, map_location)


def _load_from_ceph(filename: str, map_location=None, backend='petrel'):
    """Schemes ``s3://`` / ``petrel://``: read into memory with mmengine's
    file backend, as mmengine does."""
    from mmengine.fileio import get_file_backend
    file_backend = get_file_backend(
        filename, backend_args={'backend': backend})
    with io.BytesIO(file_backend.get(filename)) as buffer:
        return load_checkpoint_stream(buffer, filename, map_location)


#: mmengine 0.10.7's scheme prefixes -> the restricted loader of each.
SCHEMES = {
    '': _load_from_local,
    'http://': _load_from_http,
    'https://': _load_from_http,
    'torchvision://': _load_from_torchvision,
    'modelzoo://': _load_from_torchvision,
    'open-mmlab://': _load_from_openmmlab,
    'openmmlab://': _load_from_openmmlab,
    'mmcls://': _load_from_mmcls,
    'pavi://': _load_from_pavi,
    r'(\S+\:)?s3://': _load_from_ceph,
    r'(\S+\:)?petrel://': _load_from_ceph,
}


#: mmengine's loaders by prefix, as found by the first install.
_MMENGINE_SCHEMES: dict = {}


def install_checkpoint_loader() -> None:
    """Make mmengine load checkpoints of every scheme restrictedly.

    Replaces mmengine's loader of each scheme of :data:`SCHEMES`
    (``force=True``: mmengine offers no other way to choose how a scheme
    unpickles). Nothing is installed on import:
    :class:`~projects.occ_common.engine.hooks.WeightsOnlyCheckpointHook` calls
    this in ``before_run`` (before the Runner loads, resumes or
    initialises weights) and ``tools/test.py`` (``CheckpointMatchHook``)
    likewise. Calling it again does nothing more.

    Raises:
        RuntimeError: If mmengine has a scheme not in :data:`SCHEMES` (a
            newer mmengine), which would still load unrestrictedly.
    """
    from mmengine.runner.checkpoint import CheckpointLoader
    schemes = CheckpointLoader._schemes
    unknown = sorted(set(schemes) - set(SCHEMES))
    if unknown:
        raise RuntimeError(
            f'mmengine has checkpoint schemes {unknown} that the restricted '
            'loader does not serve (projects/occ_common/fileio/'
            'checkpoint_schemes.py lists those of mmengine 0.10.7); add '
            'them there.')
    if not _MMENGINE_SCHEMES and not is_installed():
        _MMENGINE_SCHEMES.update(schemes)
    for prefix, loader in SCHEMES.items():
        if schemes.get(prefix) is not loader:
            CheckpointLoader.register_scheme(
                prefixes=prefix, loader=loader, force=True)


def uninstall_checkpoint_loader() -> None:
    """Give mmengine back the loaders it had before the first install.

    What a fresh process has: the fault matrix starts each case (a forked
    child of a process that may have installed the restricted loader)
    from it, so that a guard removed by a mutation is not hidden by an
    install that happened earlier in the parent. No-op if nothing was
    installed.
    """
    from mmengine.runner.checkpoint import CheckpointLoader
    if not _MMENGINE_SCHEMES:
        return
    CheckpointLoader._schemes.clear()
    CheckpointLoader._schemes.update(_MMENGINE_SCHEMES)


def is_installed() -> bool:
    """Whether :func:`install_checkpoint_loader` has run in this process."""
    from mmengine.runner.checkpoint import CheckpointLoader
    return all(CheckpointLoader._schemes.get(prefix) is loader
               for prefix, loader in SCHEMES.items())


__all__ = [
    'SCHEMES', 'install_checkpoint_loader', 'is_installed',
    'uninstall_checkpoint_loader'
]
