"""A config's test set with a sensor corruption applied on the fly."""
import copy
from typing import Optional

from ..transforms.corruptions import CONDITIONS, with_corruption
from ..transforms.corruptions.pipeline import INPUT_LOADERS, keep_rings
from .unlabelled_pipeline import innermost_dataset


def corrupted_dataset_cfg(dataset_cfg: dict,
                          condition: Optional[str] = None,
                          severity: int = 1,
                          seed: int = 0,
                          every: int = 1) -> dict:
    """A copy of a dataset config whose samples are corrupted.

    The innermost dataset (inside any wrappers) gets
    ``OccCorruption(condition, severity, seed)`` in its pipeline (see
    :func:`~projects.occ_common.transforms.corruptions.with_corruption`),
    ``num_frames >= 2`` where the condition shows the previous key frame,
    and keeps every ``every``-th sample (its ``load_interval`` times
    ``every``).

    Args:
        dataset_cfg (dict): E.g. ``cfg.test_dataloader.dataset``.
        condition (str, optional): One of ``OccCorruption.CONDITIONS``;
            None leaves the samples clean. Defaults to None.
        severity (int): 1..5. Defaults to 1.
        seed (int): Seed of the corruption's draws. Defaults to 0.
        every (int): Keep every n-th sample. Defaults to 1 (all).

    Returns:
        dict: The new config.
    """
    if every < 1:
        raise ValueError(f'every must be >= 1, got {every}')
    dataset_cfg = copy.deepcopy(dataset_cfg)
    inner = innermost_dataset(dataset_cfg)
    inner['load_interval'] = int(inner.get('load_interval', 1)) * int(every)
    if condition is not None:
        inner['pipeline'] = with_corruption(inner['pipeline'], condition,
                                            severity, seed)
        if CONDITIONS[condition].needs == 'previous_frame':
            inner['num_frames'] = max(2, int(inner.get('num_frames', 1)))
    return dataset_cfg


def build_corrupted_dataset(cfg,
                            condition: Optional[str] = None,
                            severity: int = 1,
                            seed: int = 0,
                            every: int = 1):
    """The test dataset of ``cfg`` with :func:`corrupted_dataset_cfg`.

    Args:
        cfg (Config): A merged config; its default scope is set here.
        condition, severity, seed, every: See
            :func:`corrupted_dataset_cfg`.

    Returns:
        Dataset: The built dataset.
    """
    from mmengine.registry import DATASETS, init_default_scope

    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    return DATASETS.build(
        corrupted_dataset_cfg(cfg.test_dataloader.dataset, condition,
                              severity, seed, every))


def loaded_inputs(cfg, data_root: str, ann_file: Optional[str] = None,
                  index: int = 0) -> dict:
    """One test sample as the config's input loaders leave it: what
    ``OccCorruption`` receives.

    The test pipeline is cut after its input loaders (key frame, ego
    removal, sweeps with their ring indices kept, images) and the previous
    key frame is attached (``num_frames=2``), so that every condition
    applies; the state is returned unpacked.

    Args:
        cfg (Config): A config with a ``test_dataloader`` of this
            library's dataset (a dataset base config will do).
        data_root (str): Root of the info file's paths.
        ann_file (str, optional): Info file. Defaults to the config's.
        index (int): The sample. Defaults to 0.

    Returns:
        dict: ``img`` (uint8 views), the per-view matrices, ``points``,
        ``points_ring``, ``prev_frames``, ``lidar_sweeps``, ``token`` ...
    """
    from mmengine.registry import DATASETS, init_default_scope

    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    ds_cfg = copy.deepcopy(innermost_dataset(cfg.test_dataloader.dataset))
    ds_cfg['pipeline'] = [
        dict(t) for t in ds_cfg['pipeline'] if t['type'] in INPUT_LOADERS
    ]
    keep_rings(ds_cfg['pipeline'])
    ds_cfg.update(data_root=data_root, num_frames=2, test_mode=True)
    if ann_file is not None:
        ds_cfg['ann_file'] = ann_file
    return DATASETS.build(ds_cfg)[index]
