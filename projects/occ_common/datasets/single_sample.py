"""One sample of an info file, for inference on a user's own key frame.

``demo/occ_demo.py`` takes an info file and one sample of it (by index or
token). Two kinds of info file are accepted, told apart by their
``metainfo``:

* this library's (``tools/create_data.py``; ``info_version``
  :data:`~.info_format.INFO_VERSION`): used as it is, so a temporal
  config finds the previous key frames in it;
* mmdet3d's v2 info files (``info_version`` 1.1: samples with
  ``lidar_points`` and ``images``): the chosen sample alone is converted
  as ``tools/create_data.py --from-mmdet3d-info`` converts every sample
  (:func:`~.converters.extend_mmdet3d_infos.extend_entry`), without
  labels, and written as a one-sample info file. It has no previous key
  frame in that file: a temporal config repeats the key frame, as at a
  scene's start.

Both are read with the restricted unpickler (nothing in them can run
code). Errors name the file and the sample and say what was expected.
"""
import os
import os.path as osp
import warnings
from typing import Mapping, NamedTuple, Optional

from ..fileio.safe_names import safe_file_name
from ..fileio.safe_pickle import load_info_file
from .info_format import INFO_VERSION, check_info_file


class SampleInfo(NamedTuple):
    """Where the chosen sample is, in an info file of this library.

    Attributes:
        info_file (str): Info file of this library holding the sample.
        index (int): The sample's index in that file.
        token (str): Its nuScenes sample token.
        source (str): ``'occ'`` (the given file) or ``'mmdet3d'`` (the
            sample converted from the given mmdet3d info file).
    """

    info_file: str
    index: int
    token: str
    source: str


def info_file_kind(infos, path: str) -> str:
    """``'occ'`` or ``'mmdet3d'``: which kind of info file ``infos`` is.

    Args:
        infos: The unpickled file.
        path (str): Its name, for the messages.

    Returns:
        str: ``'occ'`` for this library's (checked with
        :func:`~.info_format.check_info_file`), ``'mmdet3d'`` for an
        mmdet3d v2 info file.

    Raises:
        ValueError: Neither kind, or this library's of another version.
    """
    expected = (f'{path}: expected an info file of tools/create_data.py '
                f'(info_version {INFO_VERSION!r}) or an mmdet3d v2 info '
                'file (dict(metainfo=..., data_list=[...]) of samples with '
                "'token', 'lidar_points' and 'images')")
    if not isinstance(infos, Mapping) or not isinstance(
            infos.get('metainfo'), Mapping) or not isinstance(
                infos.get('data_list'), list):
        keys = sorted(infos) if isinstance(infos, Mapping) else []
        raise ValueError(f'{expected}; got a {type(infos).__name__} with '
                         f'keys {keys}')
    meta = infos['metainfo']
    if meta.get('info_version') == INFO_VERSION or \
            meta.get('dataset') == 'nuscenes-occ':
        check_info_file(infos, path)  # names a version or key mismatch
        return 'occ'
    for entry in infos['data_list']:
        if not isinstance(entry, Mapping) or not all(
                key in entry for key in ('token', 'lidar_points', 'images')):
            found = sorted(entry) if isinstance(entry, Mapping) else \
                type(entry).__name__
            raise ValueError(f'{expected}; a sample of it has {found}')
    return 'mmdet3d'


def select_sample(data_list: list,
                  path: str,
                  index: Optional[int] = None,
                  token: Optional[str] = None) -> int:
    """The index of the sample given by ``index`` or ``token``.

    Args:
        data_list (list): The info file's samples.
        path (str): The file, for the messages.
        index (int, optional): Sample index. Defaults to 0 without
            ``token``.
        token (str, optional): Sample token.

    Returns:
        int: The sample's index in ``data_list``.

    Raises:
        ValueError: Both given, the index out of range (naming the
            count), or no sample with the token.
    """
    count = len(data_list)
    holds = f'{count} sample' + ('' if count == 1 else 's')
    if index is not None and token is not None:
        raise ValueError('give a sample index or a sample token, not both')
    if token is not None:
        for i, entry in enumerate(data_list):
            if entry.get('token') == token:
                return i
        raise ValueError(f'{path}: no sample has the token {token!r} (it '
                         f'holds {holds})')
    index = 0 if index is None else index
    if not 0 <= index < count:
        valid = f'0..{count - 1}' if count else 'none'
        raise ValueError(f'{path}: sample index {index} is out of range: '
                         f'the file holds {holds} (valid: {valid})')
    return index


def _convert_mmdet3d_sample(infos: dict, index: int, info_file: str,
                            data_root: str, target: str) -> str:
    """Write the one-sample info file of ``data_list[index]`` to
    ``target``."""
    from .converters.extend_mmdet3d_infos import (_Resolver, _scene_index,
                                                  extend_entry)
    from .converters.nuscenes_occ_converter import write_info_file
    from .converters.report import ConversionReport
    meta = infos['metainfo']
    version = meta.get('version', 'v1.0-trainval')
    entry = infos['data_list'][index]
    report = ConversionReport()
    # No label folders: the demo predicts, it scores nothing.
    info = extend_entry(entry, _Resolver(data_root, version, info_file),
                        _scene_index(data_root, version), (None, None), {},
                        report)
    info['prev_key_frame'] = None
    for line in report.lines():
        # The scene only selects the rainy / night evaluation subsets.
        if not line.startswith('scene unknown'):
            warnings.warn(f'{info_file}: {line}')
    os.makedirs(osp.dirname(target), exist_ok=True)
    write_info_file(target, [info], version, 'demo', synthetic=False,
                    cameras=tuple(info['images']),
                    extended_from=osp.basename(info_file),
                    mmdet3d_info_version=meta.get('info_version'))
    return target


def sample_info_file(info_file: str,
                     data_root: str,
                     out_dir: str,
                     index: Optional[int] = None,
                     token: Optional[str] = None) -> SampleInfo:
    """The chosen sample of ``info_file`` in an info file of this library.

    Args:
        info_file (str): This library's or mmdet3d's v2 info file.
        data_root (str): Root its paths are relative to.
        out_dir (str): Where the one-sample info file of an mmdet3d
            sample is written.
        index (int, optional): Sample index. Defaults to 0 without
            ``token``.
        token (str, optional): Sample token.

    Returns:
        SampleInfo: The info file to load and the sample's index in it.

    Raises:
        FileNotFoundError: ``info_file``, or the key frame or an image of
            an mmdet3d sample, does not exist (naming the file).
        ValueError: See :func:`info_file_kind` and :func:`select_sample`.
        RefusedGlobalError: The file pickles anything but containers,
            scalars and numpy arrays (nothing from it was run).
    """
    if not osp.isfile(info_file):
        raise FileNotFoundError(
            f'info file not found: {info_file}; expected an info file of '
            'tools/create_data.py or an mmdet3d v2 info file (.pkl)')
    infos = load_info_file(info_file)
    kind = info_file_kind(infos, info_file)
    chosen = select_sample(infos['data_list'], info_file, index, token)
    # Checked here, before anything is written: the token names files.
    sample_token = safe_file_name(infos['data_list'][chosen]['token'],
                                  'sample token', info_file)
    if kind == 'occ':
        return SampleInfo(info_file, chosen, sample_token, kind)
    # Named by the checked token: nothing is written outside out_dir.
    path = _convert_mmdet3d_sample(
        infos, chosen, info_file, data_root,
        osp.join(out_dir, f'{sample_token}_info.pkl'))
    return SampleInfo(path, 0, sample_token, kind)


__all__ = [
    'SampleInfo', 'info_file_kind', 'sample_info_file', 'select_sample'
]
