"""A sample as the loading transforms leave it, for the corruption tests.

:func:`loaded_sample` runs the SurroundOcc base config's test loaders
(key frame, ego removal, sweeps with their ring indices kept, images) on a
converted world, with the previous key frame attached, and stops there:
what ``OccCorruption`` receives. Tests deep-copy it and corrupt the copy,
so the loaders run once per sample.
"""
import copy
import os.path as osp
from typing import Optional

from mmengine.config import Config

from ..transforms.corruptions.pipeline import INPUT_LOADERS, SWEEPS_LOADER
from .tool_logs import REPO_ROOT

#: The base whose test loaders are used (nuScenes' cameras, 10 sweeps).
BASE = osp.join(REPO_ROOT, 'configs', '_base_', 'datasets',
                'surroundocc-nus.py')


def loaded_sample(data_root: str, index: int = 0,
                  ann_file: Optional[str] = None) -> dict:
    """The pipeline state of one sample after the loaders.

    Args:
        data_root (str): A converted world (``tools/create_data.py``).
        index (int): Sample of the val split. Defaults to 0.
        ann_file (str, optional): Another info file (e.g. the real
            sample's). Defaults to the val split's.

    Returns:
        dict: ``img`` (six uint8 views), the per-view matrices, ``points``
        (x, y, z, intensity, time lag), ``points_ring``, ``prev_frames``,
        ``lidar_sweeps``, ``token`` ...
    """
    from mmdet3d.registry import DATASETS
    from mmengine.registry import init_default_scope

    cfg = Config.fromfile(BASE)
    init_default_scope('mmdet3d')
    pipeline = [
        dict(t, record_ring=True) if t['type'] == SWEEPS_LOADER else dict(t)
        for t in cfg.test_inputs if t['type'] in INPUT_LOADERS
    ]
    ds_cfg = copy.deepcopy(cfg.test_dataloader.dataset)
    ds_cfg.update(data_root=data_root, pipeline=pipeline, num_frames=2)
    if ann_file is not None:
        ds_cfg['ann_file'] = ann_file
    return DATASETS.build(ds_cfg)[index]
