"""A config's test pipeline for samples without labels.

``tools/test.py --format-only`` and ``demo/occ_demo.py`` predict on samples
that have no occupancy or lidarseg labels (the ``v1.0-test`` split, a
user's own key frame). Their test pipeline keeps ``LoadOccupancyGT``, which
then allows a sample without a label (``allow_unlabelled=True``: nothing
is scored, the metainfo it adds stays), and drops the steps that only read
lidarseg labels or turn them into training targets (no prediction uses
them). Like the tools, this module imports no plugin code.
"""
import copy
import os.path as osp
from typing import List, Mapping, Sequence

#: Test-pipeline steps that only read labels or make training targets from
#: them.
LABEL_ONLY_STEPS = ('LoadLidarSegLabels', 'PointsToSemanticMaps')


def innermost_dataset(dataset_cfg: Mapping) -> Mapping:
    """The dataset config that holds the pipeline, inside any wrappers.

    Args:
        dataset_cfg (Mapping): ``cfg.test_dataloader.dataset``, maybe a
            wrapper (``dict(type=..., dataset=dict(...))``).

    Returns:
        Mapping: The innermost config with a ``pipeline`` (the same
        object, so that changing it changes ``dataset_cfg``).
    """
    dataset = dataset_cfg
    while 'pipeline' not in dataset and 'dataset' in dataset:
        dataset = dataset['dataset']
    return dataset


def unlabelled_pipeline(pipeline: Sequence[Mapping]) -> List[dict]:
    """``pipeline`` for samples without labels.

    Args:
        pipeline (Sequence[Mapping]): Test-pipeline step configs.

    Returns:
        list[dict]: New step configs: ``LoadOccupancyGT`` with
        ``allow_unlabelled=True``, :data:`LABEL_ONLY_STEPS` left out, the
        rest unchanged.
    """
    return [
        dict(step, allow_unlabelled=True)
        if step.get('type') == 'LoadOccupancyGT' else dict(step)
        for step in pipeline
        if step.get('type') not in LABEL_ONLY_STEPS
    ]


__all__ = ['LABEL_ONLY_STEPS', 'innermost_dataset', 'unlabelled_pipeline']


def unlabelled_test_dataset(cfg, info_file: str, data_root: str):
    """The config's test dataset on another info file, unlabelled.

    What ``demo/occ_demo.py`` and ``tools/deployment/export_onnx.py`` read
    a user's sample through: the innermost test dataset of ``cfg`` with
    ``info_file``, every sample (``load_interval=1``) and
    :func:`unlabelled_pipeline`.

    Args:
        cfg (Config): The config.
        info_file (str): Info file of the samples.
        data_root (str): Root of the info file's paths.

    Returns:
        BaseDataset: The dataset.
    """
    from mmdet3d.registry import DATASETS
    ds_cfg = copy.deepcopy(innermost_dataset(cfg.test_dataloader.dataset))
    ds_cfg.update(
        data_root=data_root,
        ann_file=osp.abspath(info_file),
        test_mode=True,
        load_interval=1,
        pipeline=unlabelled_pipeline(ds_cfg['pipeline']))
    return DATASETS.build(ds_cfg)
