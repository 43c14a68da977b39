"""The samples of a split through a config's test pipeline, for the
analysis tools (``--split`` and ``--data-root`` on their command lines)."""
import argparse
from typing import Optional


def add_split_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--split {val,train}`` and ``--data-root`` to ``parser``."""
    parser.add_argument('--split', choices=('val', 'train'), default='val',
                        help='the test dataloader\'s samples, or the '
                        'training set\'s through the test pipeline')
    parser.add_argument('--data-root', default=None,
                        help='override the dataset\'s data_root')


def build_split_dataset(cfg, split: str = 'val',
                        data_root: Optional[str] = None):
    """The dataset of ``split``, always through the test pipeline.

    ``train`` measures the training scenes without augmentation, to tell a
    model that underfits from one that does not generalise.

    Args:
        cfg (Config): A merged config; its default scope is set here.
        split (str): 'val' (the test dataloader's) or 'train'.
        data_root (str, optional): Replaces the dataset's ``data_root``.

    Returns:
        Dataset: The built dataset.
    """
    from mmengine.registry import DATASETS, init_default_scope

    if split not in ('val', 'train'):
        raise ValueError(f"split must be 'val' or 'train', got {split!r}")
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    ds_cfg = cfg.test_dataloader.dataset.copy()
    if split == 'train':
        ds_cfg = dict(cfg.train_dataloader.dataset,
                      pipeline=ds_cfg['pipeline'], test_mode=True)
    if data_root is not None:
        ds_cfg['data_root'] = data_root
    return DATASETS.build(ds_cfg)
