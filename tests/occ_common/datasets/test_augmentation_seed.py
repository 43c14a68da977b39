"""Random augmentation seeded per (seed, epoch, sample index).

The pipeline is the tiny SDG-Fusion's training pipeline (image resize /
crop / flip / rotation per view and BEV flips) on the converted tiny
world.
"""
import random
import types

import numpy as np
import pytest
import torch
from mmdet3d.registry import DATASETS
from mmdet3d.utils import register_all_modules
from mmengine.config import Config
from mmengine.dataset import pseudo_collate
from torch.utils.data import DataLoader

import projects.occ_common  # noqa: F401  (registers)
from projects.occ_common.datasets.augmentation_seed import EpochSeed
from projects.occ_common.engine.hooks import AugmentationSeedHook
from projects.occ_common.testing.tool_logs import REPO_ROOT

register_all_modules(init_default_scope=True)
CONFIG = (f'{REPO_ROOT}/configs/sdg_occ/'
          'sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py')


@pytest.fixture(scope='module')
def dataset_cfg(converted_tiny_world):
    cfg = Config.fromfile(CONFIG).train_dataloader.dataset
    cfg.data_root = converted_tiny_world.rstrip('/') + '/'
    return cfg


def _fetch(dataset, epoch, index):
    dataset.set_augmentation_seed(0, epoch)
    return dataset[index]


def _aug(sample):
    meta = sample['data_samples'].metainfo
    return meta['img_aug_params'], meta['bda_params']


def _same(a, b):
    return (torch.equal(a['inputs']['img'], b['inputs']['img'])
            and torch.equal(a['inputs']['points'], b['inputs']['points'])
            and _aug(a) == _aug(b))


def test_same_seed_epoch_and_index_give_the_same_sample(dataset_cfg):
    """Two datasets, global generators disturbed in between: identical
    images, points and drawn parameters; another epoch draws anew; the
    global generators are left as they were."""
    first, second = DATASETS.build(dataset_cfg), DATASETS.build(dataset_cfg)
    state = (np.random.get_state()[1].copy(), random.getstate(),
             torch.get_rng_state())
    a = _fetch(first, 1, 0)
    assert np.array_equal(np.random.get_state()[1], state[0])
    assert random.getstate() == state[1]
    assert torch.equal(torch.get_rng_state(), state[2])
    np.random.rand(7), random.random(), torch.rand(3)
    assert _same(a, _fetch(second, 1, 0))
    other_epoch = _fetch(first, 2, 0)
    assert _aug(other_epoch)[0] != _aug(a)[0]
    assert not torch.equal(other_epoch['inputs']['img'], a['inputs']['img'])


def test_persistent_workers_load_what_the_main_process_loads(dataset_cfg):
    """Two persistent workers over two epochs, the epoch set between them
    (through shared memory): every sample equals the main-process fetch."""
    reference = DATASETS.build(dataset_cfg)
    dataset = DATASETS.build(dataset_cfg)
    dataset.set_augmentation_seed(0, 0)
    loader = DataLoader(dataset, batch_size=1, num_workers=2,
                        persistent_workers=True, collate_fn=pseudo_collate)
    for epoch in range(2):
        dataset.set_augmentation_seed(0, epoch)
        for index, batch in enumerate(loader):
            expected = _fetch(reference, epoch, index)
            sample = dict(inputs=dict(img=batch['inputs']['img'][0],
                                      points=batch['inputs']['points'][0]),
                          data_samples=batch['data_samples'][0])
            assert _same(sample, expected), (epoch, index)


def test_hook_reaches_wrapped_datasets_and_validates():
    """before_train_epoch seeds every dataset inside wrappers."""
    inner = [types.SimpleNamespace(seen=None) for _ in range(2)]
    for dataset in inner:
        dataset.set_augmentation_seed = (
            lambda s, e, d=dataset: setattr(d, 'seen', (s, e)))
    wrapper = types.SimpleNamespace(datasets=[
        types.SimpleNamespace(dataset=inner[0]), inner[1]
    ])
    runner = types.SimpleNamespace(
        seed=5, epoch=3,
        train_dataloader=types.SimpleNamespace(dataset=wrapper))
    AugmentationSeedHook().before_train_epoch(runner)
    assert [d.seen for d in inner] == [(5, 3), (5, 3)]
    with pytest.raises(ValueError, match='seed >= 0'):
        EpochSeed().set(-1, 0)
    assert EpochSeed().get() is None
