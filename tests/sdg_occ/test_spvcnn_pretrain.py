"""The release's LiDAR-side start: SPVCNN pre-trained on lidarseg, then
loaded into the SDG-OCC model through the checked ``pretrained`` entry.

``configs/sdg_occ/pretrain/spvcnn_4xb4-24e_nus-lidarseg.py`` trains one
epoch (two iterations, batch 1) on the tests' tiny world's lidarseg labels
with its paper-size encoder (0.1 m voxels); the checkpoint it saves then
loads into the paper SDG-Fusion config's ``lidar_encoder`` with
``pretrained.lidar_encoder.checkpoint`` set, every tensor but the BEV
projection (which the pre-training has not) equal to the file's.
"""
import copy
import glob
import os.path as osp

import pytest
import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope
from mmengine.runner import Runner

from projects.occ_common.testing.tool_logs import (REPO_ROOT, quiet_logger,
                                                   train_losses)
from projects.sdg_occ import SPVCNNSegmentor

CONFIG = osp.join(REPO_ROOT, 'configs', 'sdg_occ', 'pretrain',
                  'spvcnn_4xb4-24e_nus-lidarseg.py')
FUSION = osp.join(REPO_ROOT,
                  'configs/sdg_occ/sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py')


@pytest.fixture(scope='module')
def pretrained(converted_tiny_world, tmp_path_factory):
    """Work dir, first weights and checkpoint of a one-epoch pre-training."""
    cfg = Config.fromfile(CONFIG)
    work_dir = str(tmp_path_factory.mktemp('spvcnn'))
    cfg.merge_from_dict({
        'work_dir': work_dir,
        'train_dataloader.batch_size': 1,
        'train_dataloader.num_workers': 0,
        'train_dataloader.persistent_workers': False,
        'train_dataloader.pin_memory': False,
        'train_dataloader.dataset.data_root': converted_tiny_world,
        'train_cfg.max_epochs': 1,
        'default_hooks.logger.interval': 1,
        'log_processor.window_size': 1,
        'randomness.seed': 0,
    })
    runner = Runner.from_cfg(cfg)
    first = copy.deepcopy(runner.model.state_dict())
    runner.train()
    [checkpoint] = glob.glob(osp.join(work_dir, 'epoch_1.pth'))
    return work_dir, first, runner.model, checkpoint


def test_pretraining_trains_the_encoder_on_lidarseg(pretrained):
    """Two iterations (the tiny world's two key frames) with a finite
    point segmentation loss of the order ln 17 = 2.83 at the start (17
    classes, near-uniform logits), and every encoder and head parameter
    moved by them."""
    work_dir, first, model, _ = pretrained
    assert isinstance(model, SPVCNNSegmentor)
    losses = train_losses(work_dir)
    assert len(losses) == 2 and all(torch.isfinite(torch.tensor(losses)))
    assert 1.0 < losses[0] < 6.0
    state = model.state_dict()
    moved = [k for k, v in state.items() if v.is_floating_point()
             and not torch.equal(v, first[k])]
    weights = [k for k in state if k.endswith('weight')]
    assert set(weights) <= set(moved)
    assert not any(k.startswith('lidar_encoder.bev_proj') for k in state)


def test_checkpoint_loads_into_the_fusion_model(pretrained):
    """The paper SDG-Fusion config with the checkpoint as its
    ``pretrained.lidar_encoder``: init_weights loads all the encoder's
    tensors from the file (the BEV projection keeps its initialisation,
    reported as allowed missing)."""
    _, _, model, checkpoint = pretrained
    cfg = Config.fromfile(FUSION)
    cfg.merge_from_dict({
        'model.pretrained.img_backbone.checkpoint': None,
        'model.pretrained.lidar_encoder.checkpoint': checkpoint,
    })
    init_default_scope('mmdet3d')
    fusion = MODELS.build(cfg.model)
    with quiet_logger():
        fusion.init_weights()
    trained = model.lidar_encoder.state_dict()
    loaded = fusion.lidar_encoder.state_dict()
    assert set(loaded) - set(trained) == {
        k for k in loaded if k.startswith('bev_proj.')} != set()
    for key, value in trained.items():
        assert torch.equal(loaded[key], value), key
