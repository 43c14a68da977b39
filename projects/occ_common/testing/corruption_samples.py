"""A sample as the loading transforms leave it, for the corruption tests.

:func:`loaded_sample` runs the SurroundOcc base config's test loaders
(key frame, ego removal, sweeps with their ring indices kept, images) on a
converted world, with the previous key frame attached, and stops there:
what ``OccCorruption`` receives. Tests deep-copy it and corrupt the copy,
so the loaders run once per sample.
"""
import os.path as osp
from typing import Optional

from mmengine.config import Config

from ..apis.corrupted_dataset import loaded_inputs
from .tool_logs import REPO_ROOT

#: The base whose test loaders are used (nuScenes' cameras, 10 sweeps).
BASE = osp.join(REPO_ROOT, 'configs', '_base_', 'datasets',
                'surroundocc-nus.py')


def loaded_sample(data_root: str, index: int = 0,
                  ann_file: Optional[str] = None) -> dict:
    """:func:`~projects.occ_common.apis.loaded_inputs` of the SurroundOcc
    base on ``data_root`` (its val split unless ``ann_file``)."""
    return loaded_inputs(Config.fromfile(BASE), data_root, ann_file, index)
