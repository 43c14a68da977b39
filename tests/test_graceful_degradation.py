"""Every model predicts, finitely, when a sensor is gone.

Each model of the library at its tiny size (OccCylindrical, SDG-Fusion
single- and two-frame, SDG-KL's student, and SDG-OCC's two camera rows of
Table 3) gets a tiny-world test sample corrupted as
``tools/analysis_tools/robustness.py`` corrupts it, in three cases: no
LiDAR point at all, every camera black (calibration kept), and three of
the six views missing (image and calibration gone). The sample is checked
to really be degraded, and the model's class logits over the whole grid
must be finite. Weights are the initialisation:
the paths under test (empty point sets in the point branches and the
SDG lift, constant images through the norms, fewer views in the lifts)
are the same for trained weights, which the robustness report runs.
"""
import argparse
import os.path as osp

import pytest
import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config, DictAction
from mmengine.dataset import pseudo_collate
from mmengine.registry import init_default_scope

from projects.occ_common.apis import build_corrupted_dataset
from projects.occ_common.testing.tool_logs import REPO_ROOT, load_tool

_SDG = 'configs/sdg_occ/sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py'
_LEARNING = 'tools/analysis_tools/benchmark_learning.py'
#: name -> (config, --cfg-options of the benchmark's runs).
MODELS_UNDER_TEST = {
    'occcyl': ('configs/occ_cyl/'
               'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py', []),
    'sdg-fusion': (_SDG, []),
    'sdg-fusion-2f': ('configs/sdg_occ/'
                      'sdgocc-fusion-2f_tiny_1xb1-6e_occ3d-nus-synthetic.py',
                      []),
    'sdg-kl-student': ('configs/sdg_occ/'
                       'sdgocc-kl_tiny_1xb1-6e_occ3d-nus-synthetic.py', []),
    'sdg-camera-sdg': (_SDG, '_CAMERA_SDG'),
    'sdg-camera-lss': (_SDG, '_CAMERA_LSS'),
}
#: case -> (condition, severity).
CASES = {
    'no LiDAR': ('lidar_missing', 5),
    'all cameras black': ('camera_blackout', 5),
    '3 of 6 views missing': ('missing_views', 3),
}


def _config(name: str, root: str) -> Config:
    path, options = MODELS_UNDER_TEST[name]
    cfg = Config.fromfile(osp.join(REPO_ROOT, path))
    if options:
        parser = argparse.ArgumentParser()
        parser.add_argument('--o', nargs='+', action=DictAction)
        deltas = getattr(load_tool(_LEARNING), options)
        cfg.merge_from_dict(parser.parse_args(['--o', *deltas]).o)
    cfg.test_dataloader.dataset.data_root = root
    return cfg


@pytest.fixture(scope='module')
def built(converted_tiny_world):
    """Config and model of each name, built once."""
    cache = {}

    def get(name):
        if name not in cache:
            cfg = _config(name, converted_tiny_world)
            init_default_scope('mmdet3d')
            torch.manual_seed(0)
            model = MODELS.build(cfg.model)
            model.init_weights()
            cache[name] = (cfg, model.eval())
        return cache[name]

    return get


#: The fast tier runs each case once, each on another model; the slow tier
#: the rest of the matrix (a tiny SDG-OCC forward takes seconds).
FAST = {('occcyl', 'no LiDAR'), ('sdg-fusion', 'all cameras black'),
        ('sdg-kl-student', '3 of 6 views missing')}


@pytest.mark.parametrize('name, case', [
    pytest.param(n, c, marks=() if (n, c) in FAST else pytest.mark.slow)
    for n in MODELS_UNDER_TEST for c in CASES
])
def test_model_predicts_without_a_sensor(built, name, case):
    cfg, model = built(name)
    condition, severity = CASES[case]
    # The second key frame: the two-frame model's previous one is real.
    sample = build_corrupted_dataset(cfg, condition, severity)[1]
    with torch.no_grad():
        data = model.data_preprocessor(pseudo_collate([sample]), False)
        imgs = data['inputs']['imgs']
        if condition == 'lidar_missing':
            assert len(data['inputs']['points'][0]) == 0
        elif condition == 'camera_blackout':
            # The current frame's views (a two-frame model's previous ones
            # come after them, from a frame the cameras still saw): black
            # pixels normalise to one value per channel.
            flat = imgs[:, :6].flatten(3)
            assert (flat == flat[..., :1]).all()
        else:
            frames = getattr(model, 'num_frames', 1)
            assert imgs.shape[1] == 3 * frames
            assert all(len(s.lidar2img) == 3 for s in data['data_samples'])
        # The inference path's logits (predict takes their argmax;
        # tools/analysis_tools/robustness.py --ece checks that it does).
        logits = model(**data, mode='tensor')
        logits = logits[0] if isinstance(logits, (list, tuple)) else logits
    assert tuple(logits.shape) == (1, model.num_classes, *model.occ_shape)
    assert torch.isfinite(logits).all()
