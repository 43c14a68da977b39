"""The samples of a split through a config's test pipeline, for the
analysis tools (``--split`` and ``--data-root`` on their command lines)."""
import argparse
from typing import Iterator, Optional


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


def load_tool_config(args: argparse.Namespace):
    """``args.config`` with ``args.cfg_options`` checked and merged in, as
    ``tools/train.py`` and ``tools/test.py`` do (:func:`apply_cfg_options`).

    ``Config.fromfile`` imports the config's ``custom_imports`` (the
    plugins), so the registries are filled afterwards.
    """
    from mmengine.config import Config

    from ..engine.config_checks import apply_cfg_options

    cfg = Config.fromfile(args.config)
    apply_cfg_options(cfg, args)
    return cfg


def labelled_samples(cfg, split: str = 'val',
                     data_root: Optional[str] = None) -> Iterator[tuple]:
    """The samples of a split with their occupancy labels, checked.

    Args:
        cfg (Config): A merged config with ``grid_size``.
        split (str): See :func:`build_split_dataset`.
        data_root (str, optional): See :func:`build_split_dataset`.

    Yields:
        tuple[dict, np.ndarray]: The packed sample and its ``gt_occ`` as
        numpy, Shape (X, Y, Z).

    Raises:
        ValueError: A sample without labels of the config's grid, named by
            its info file and index.
    """
    dataset = build_split_dataset(cfg, split, data_root)
    grid = tuple(cfg.grid_size)
    for index in range(len(dataset)):
        sample = dataset[index]
        occ = sample['data_samples'].get('gt_occ')
        if occ is None or tuple(occ.shape) != grid:
            raise ValueError(
                f'{dataset.ann_file}, sample {index}: expected occupancy '
                f'labels of the config\'s grid_size {grid}, got ' +
                ('none' if occ is None else str(tuple(occ.shape))))
        yield sample, occ.numpy()
