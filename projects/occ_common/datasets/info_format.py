"""The schema of the occupancy info files, shared by converter and dataset.

The converter (:mod:`.converters.nuscenes_occ_converter`) writes and the
dataset (:class:`.NuScenesOccDataset`) reads these pickles; both import the
constants from here so that the version check cannot drift. Importing this
module needs neither nuscenes-devkit nor mmdet3d.

An info file is ``dict(metainfo=..., data_list=[...])`` in mmdet3d's v2
layout; :data:`INFO_VERSION` is bumped whenever a key changes meaning, so an
info file written by another converter (or an older one) is refused instead
of being misread.
"""
import re
from typing import Mapping, Sequence, Tuple

import numpy as np

#: Version of the info-file schema written by this converter.
INFO_VERSION = 'occ-nus-1.0'

#: Camera order of mmdet3d's nuScenes infos; the multi-view loader stacks
#: the views in this order unless a config says otherwise.
CAMERA_NAMES = ('CAM_FRONT', 'CAM_FRONT_RIGHT', 'CAM_FRONT_LEFT', 'CAM_BACK',
                'CAM_BACK_LEFT', 'CAM_BACK_RIGHT')

#: Values per LiDAR point in nuScenes ``.pcd.bin`` files:
#: x, y, z, intensity, ring index (float32 each). Other LiDARs record
#: theirs in the info file's ``lidar_points.num_pts_feats``.
NUM_POINT_FEATS = 5


def camera_order(names: Sequence[str]) -> Tuple[str, ...]:
    """The order in which an info file lists a rig's cameras.

    Args:
        names (Sequence[str]): The rig's camera channels, each once.

    Returns:
        tuple[str, ...]: nuScenes' six cameras in mmdet3d's order
        (:data:`CAMERA_NAMES`) when ``names`` are those six, any other
        rig's cameras in the given order.
    """
    names = tuple(dict.fromkeys(names))
    return CAMERA_NAMES if set(names) == set(CAMERA_NAMES) else names


#: Keys every ``data_list`` entry carries (checked on load).
REQUIRED_SAMPLE_KEYS = ('sample_idx', 'token', 'timestamp', 'scene_token',
                        'scene_name', 'is_rainy', 'is_night', 'ego2global',
                        'lidar_points', 'lidar_sweeps', 'images',
                        'pts_semantic_mask_path', 'occ_surroundocc_path',
                        'occ_occ3d_path')

#: Split names written by the converter, as ``<prefix>_infos_<split>.pkl``.
SPLITS = ('train', 'val', 'val_rainy', 'val_night')


def check_info_file(infos: Mapping, path: str) -> None:
    """Refuse an info file that this library's converter did not write.

    Args:
        infos (Mapping): The loaded pickle.
        path (str): Its file name, for the error message.

    Raises:
        ValueError: If the layout is not ``dict(metainfo, data_list)``
            (``metainfo`` a dict, ``data_list`` a list of dicts), the
            ``info_version`` differs from :data:`INFO_VERSION`, a sample
            lacks one of :data:`REQUIRED_SAMPLE_KEYS`, or a sample token
            appears twice (it would be trained on and evaluated twice).
    """
    if not isinstance(infos, Mapping) or 'data_list' not in infos \
            or 'metainfo' not in infos:
        raise ValueError(
            f'{path}: expected an info file dict(metainfo=..., data_list=...)'
            f' written by tools/create_data.py, got {type(infos).__name__}'
            f' with keys {sorted(infos) if isinstance(infos, Mapping) else []}'
        )
    if not isinstance(infos['metainfo'], Mapping):
        raise ValueError(
            f'{path}: metainfo must be a dict (of info_version, classes, '
            f'...), got {type(infos["metainfo"]).__name__} '
            f'{infos["metainfo"]!r:.60}')
    if not isinstance(infos['data_list'], list):
        raise ValueError(
            f'{path}: data_list must be a list of samples, got '
            f'{type(infos["data_list"]).__name__}')
    found = infos['metainfo'].get('info_version')
    if found != INFO_VERSION:
        raise ValueError(
            f'{path}: info_version {found!r} does not match the expected '
            f'{INFO_VERSION!r}; the file comes from another converter or an '
            'older version of it. Re-create it with tools/create_data.py '
            '--overwrite.')
    first_index = {}
    for index, entry in enumerate(infos['data_list']):
        if not isinstance(entry, Mapping):
            raise ValueError(
                f'{path}: sample {index} of data_list is a '
                f'{type(entry).__name__} ({entry!r:.60}), not a dict of '
                'sample keys')
        missing = [k for k in REQUIRED_SAMPLE_KEYS if k not in entry]
        if missing:
            raise ValueError(
                f'{path}: sample {entry.get("token", "?")} lacks the keys '
                f'{missing} of info_version {INFO_VERSION!r}')
        token = entry['token']
        if token in first_index:
            raise ValueError(
                f'{path}: sample {token} appears twice in data_list (at '
                f'{first_index[token]} and {index}): it would be trained '
                'on and evaluated twice. Re-create the info file with '
                'tools/create_data.py --overwrite.')
        first_index[token] = index


def as_matrix(value,
              shapes: Sequence[Tuple[int, int]],
              where: str) -> np.ndarray:
    """A calibration / pose matrix of an info file, checked.

    Args:
        value: The nested list (or array) of the info file.
        shapes (Sequence[tuple[int, int]]): Accepted shapes, e.g.
            ``[(4, 4)]`` or ``[(3, 3), (4, 4)]`` for ``cam2img``.
        where (str): File, sample and key, for the error message.

    Returns:
        np.ndarray: The matrix, float64.

    Raises:
        ValueError: If it is not numeric, has another shape, or holds NaN
            or inf.
    """
    expected = ' or '.join(f'{r}x{c}' for r, c in shapes)
    try:
        mat = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f'{where}: expected a {expected} matrix of numbers,'
                         f' got {value!r:.80} ({err})') from None
    if tuple(mat.shape) not in [tuple(s) for s in shapes]:
        raise ValueError(f'{where}: expected a {expected} matrix, got shape '
                         f'{tuple(mat.shape)}')
    if not np.isfinite(mat).all():
        raise ValueError(f'{where}: the matrix holds NaN or inf: '
                         f'{mat.tolist()}')
    return mat


def weather_flags(description: str) -> dict:
    """Rain and night flags from a nuScenes scene description.

    nuScenes has no weather table; its scene descriptions mention "rain" and
    "night" in free text (e.g. "Night, rain, parking lot"), which is how
    the rainy / night evaluation subsets are usually drawn.

    Args:
        description (str): ``scene['description']``.

    Returns:
        dict: ``is_rainy`` and ``is_night`` (bool).
    """
    # Word starts, so that "terrain", "train" or "overnight" do not count.
    text = description.lower()
    return dict(
        is_rainy=re.search(r'\brain', text) is not None,
        is_night=re.search(r'\bnight', text) is not None)
