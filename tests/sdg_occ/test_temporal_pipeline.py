"""The two-frame tiny SDG-Fusion through its own test pipeline, with and
without the test-time cache, on a synthetic scene of three key frames."""
import os.path as osp

import pytest
import torch
from mmdet3d.registry import DATASETS, MODELS
from mmengine.config import Config
from mmengine.dataset import pseudo_collate
from mmengine.registry import init_default_scope

from projects.occ_common.testing.tiny_world import make_tiny_world
from projects.occ_common.testing.tool_logs import REPO_ROOT, run_create_data

CONFIG = osp.join(REPO_ROOT, 'configs', 'sdg_occ',
                  'sdgocc-fusion-2f_tiny_1xb1-6e_occ3d-nus-synthetic.py')


@pytest.fixture(scope='module')
def three_frame_world(tmp_path_factory):
    root = make_tiny_world(str(tmp_path_factory.mktemp('three_frames')),
                           samples_per_scene=3, sweeps_per_sample=1)
    with pytest.warns(UserWarning, match='one scene'):
        run_create_data('--root-path', root, '--version', 'v1.0-mini')
    return root


@pytest.mark.filterwarnings('ignore:synthetic world with one scene')
def test_cache_equals_recomputation_through_the_pipeline(three_frame_world):
    """Key frames 0, 1, 2 in order (a sequential test loader): with the
    cache, frame k's previous camera BEV is the one computed when frame
    k-1 was current (2 of 3 frames reuse one; frame 0 reuses its own);
    without it, it is recomputed from LoadPreviousKeyFrames' images and
    points. The logits agree within 1e-4, as the previous frames get the
    current frame's image augmentation and point filters; the backbone
    runs 3 times instead of 6."""
    cfg = Config.fromfile(CONFIG)
    for module in cfg.custom_imports['imports']:
        __import__(module)
    init_default_scope('mmdet3d')
    ds_cfg = cfg.test_dataloader.dataset
    ds_cfg.update(data_root=three_frame_world,
                  ann_file='nuscenes_occ_infos_train.pkl')
    dataset = DATASETS.build(ds_cfg)
    assert len(dataset) == 3
    samples = [dataset[i] for i in range(3)]
    tokens = [s['data_samples'].metainfo['token'] for s in samples]
    assert [s['data_samples'].metainfo['prev_tokens'] for s in samples] \
        == [[tokens[0]], [tokens[0]], [tokens[1]]]
    logits = {}
    for cached in (False, True):
        torch.manual_seed(0)
        model = MODELS.build(dict(cfg.model, test_cache=cached)).eval()
        calls = []
        model.img_backbone.register_forward_pre_hook(
            lambda *args: calls.append(1))
        with torch.no_grad():
            logits[cached] = [
                model(**model.data_preprocessor(pseudo_collate([s]), False),
                      mode='tensor') for s in samples
            ]
        assert len(calls) == (3 if cached else 6)
    for a, b in zip(logits[False], logits[True]):
        assert torch.allclose(a, b, atol=1e-4, rtol=1e-4), (a - b).abs().max()
