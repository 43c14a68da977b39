"""The SDG-OCC configs are deltas that state each fact once.

test_all_configs.py builds every config and compares its model with the
committed fingerprint; test_tiny_configs.py trains the tiny ones.
"""
import glob
import os.path as osp
import re

import pytest
from mmengine.config import Config

from projects.occ_common.testing.config_delta import (coupled_value_mismatches,
                                                      model_delta)

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG_DIR = osp.join(ROOT, 'configs', 'sdg_occ')
MODEL_BASE = osp.join(CONFIG_DIR, '_base_', 'sdgocc-fusion_r50.py')
MAIN = sorted(glob.glob(osp.join(CONFIG_DIR, '*.py')))
ABLATIONS = sorted(glob.glob(osp.join(CONFIG_DIR, 'ablations', '*.py')))
TINY = [path for path in MAIN if '_tiny_' in path]


def _tiny(variant):
    return osp.join(CONFIG_DIR,
                    f'sdgocc-{variant}_tiny_1xb1-6e_occ3d-nus-synthetic.py')


TINY_FUSION = _tiny('fusion')


def _small(variant):
    return osp.join(CONFIG_DIR,
                    f'sdgocc-{variant}_small_1xb1-20e_occ3d-nus-synthetic.py')


def _main(variant, dataset):
    return osp.join(CONFIG_DIR, f'sdgocc-{variant}_r50_4xb2-24e_{dataset}.py')


FUSION = _main('fusion', 'occ3d-nus')
KL = _main('kl', 'occ3d-nus')
FUSION_SOCC = _main('fusion', 'surroundocc-nus')
FUSION_2F = _main('fusion-2f', 'occ3d-nus')
#: What each config changes in the model of the config it builds on.
COUPLED = {
    'point_cloud_range', 'voxel_size', 'num_classes', 'empty_index',
    'depth_bound'
}
KL_KEYS = {
    'loss_distill.type', 'loss_distill.alpha',
    'loss_distill.beta', 'loss_distill.loss_weight', 'kl_losses'
}
#: Table 3's rows without the SDG lift also drop its semantic head.
NO_SDG_KEYS = {'view_transform.use_sdg', 'depth_net.seg_channels', 'loss_seg'}
#: Table 3's camera-only rows: no LiDAR encoder, no fusion (nor the
#: encoder's point segmentation head and pretrained entry).
CAMERA_KEYS = {
    'lidar_encoder', 'fusion', 'point_seg_head', 'pretrained.lidar_encoder'
}
DELTAS = {
    FUSION: (MODEL_BASE, COUPLED | {'loss_mask_key'}),
    # SurroundOcc: a LiDAR voxel that divides the 0.5 m cell and the SCAL
    # terms (no camera mask).
    FUSION_SOCC: (MODEL_BASE, COUPLED | {
        'lidar_encoder.voxel_size', 'occ_head.loss_occ.losses[1].type',
        'occ_head.loss_occ.losses[1].mode',
        'occ_head.loss_occ.losses[2].type', 'occ_head.loss_occ.losses[2].mode'
    }),
    KL: (FUSION, KL_KEYS),
    # RayIoU (issue 49): the Occ3D configs trained on whole grids.
    FUSION.replace('occ3d-nus', 'occ3d-nus-nomask'): (FUSION,
                                                      {'loss_mask_key'}),
    KL.replace('occ3d-nus', 'occ3d-nus-nomask'): (KL, {'loss_mask_key'}),
    TINY_FUSION.replace('occ3d-nus', 'occ3d-nus-nomask'): (TINY_FUSION,
                                                           {'loss_mask_key'}),
    _main('kl', 'surroundocc-nus'): (FUSION_SOCC, KL_KEYS),
    _tiny('kl'): (TINY_FUSION, KL_KEYS),
    # The learning benchmark's small configs: the tiny model with sweeps
    # and a longer schedule (data and schedule only), and its SDG-KL.
    _small('fusion'): (TINY_FUSION, set()),
    _small('kl'): (_small('fusion'), KL_KEYS),
    _small('fusion').replace('occ3d-nus', 'occ3d-nus-nomask'): (
        _small('fusion'), {'loss_mask_key'}),
    _small('kl').replace('occ3d-nus', 'occ3d-nus-nomask'): (
        _small('kl'), {'loss_mask_key'}),
    # The four-camera rig without LiDAR ring index: data only.
    TINY_FUSION.replace('occ3d-nus', 'occ3d-quad'): (TINY_FUSION, set()),
    # The temporal variants (T = 2): the frame count, nothing else.
    FUSION_2F: (FUSION, {'num_frames'}),
    _tiny('fusion-2f'): (TINY_FUSION, {'num_frames'}),
    # Table 3: Baseline, +SDG, +FOAD (SDG + FOAD is FUSION itself).
    'sdgocc-camera-lss': (FUSION, CAMERA_KEYS | NO_SDG_KEYS),
    'sdgocc-camera-sdg': (FUSION, CAMERA_KEYS),
    'sdgocc-fusion-lss': (FUSION, NO_SDG_KEYS),
    # ... and its rows and SDG-KL over two frames: the same deltas on the
    # two-frame SDG-Fusion.
    'sdgocc-camera-lss-2f': (FUSION_2F, CAMERA_KEYS | NO_SDG_KEYS),
    'sdgocc-camera-sdg-2f': (FUSION_2F, CAMERA_KEYS),
    'sdgocc-fusion-lss-2f': (FUSION_2F, NO_SDG_KEYS),
    _main('kl-2f', 'occ3d-nus'): (FUSION_2F, KL_KEYS),
}


def _name(path):
    return osp.basename(path).split('_')[0] if '/ablations/' in path else path


def test_config_inventory():
    """Both variants on both datasets, as tiny and small synthetic configs,
    and the deltas of Tables 3 (3 files, and the two camera rows over two
    frames, and the three of them over two frames; SDG + FOAD is the main
    fusion config), 4 (6) and 5 (4)."""
    names = {osp.basename(p) for p in MAIN}
    for variant in ('fusion', 'kl'):
        for dataset in ('occ3d-nus', 'surroundocc-nus'):
            assert osp.basename(_main(variant, dataset)) in names
        assert osp.basename(_tiny(variant)) in names
        assert osp.basename(_small(variant)) in names
    assert len(ABLATIONS) == 16
    table3 = sorted(_name(p) for p in ABLATIONS if _name(p) in DELTAS)
    assert table3 == [
        'sdgocc-camera-lss', 'sdgocc-camera-lss-2f', 'sdgocc-camera-sdg',
        'sdgocc-camera-sdg-2f', 'sdgocc-fusion-lss', 'sdgocc-fusion-lss-2f'
    ]


@pytest.mark.parametrize(
    'path', [p for p in MAIN if p != TINY_FUSION] + ABLATIONS,
    ids=lambda p: osp.basename(p)[:-3])
def test_each_delta_changes_only_its_documented_keys(path):
    """Compared with the config it builds on, a config changes exactly the
    model keys listed in DELTAS; Tables 4 and 5 one knob each (r and the
    layers, k), the paper's own values (r = 1, 8 layers; k = 7) none."""
    name = _name(path)
    if name in DELTAS:
        parent, keys = DELTAS[name]
    elif match := re.search(r'-r(\d)l(\d+)$', name):
        parent = FUSION
        keys = {
            key
            for key, changed in (('view_transform.layer_radius',
                                  match[1] != '1'),
                                 ('view_transform.num_layers',
                                  match[2] != '8')) if changed
        }
    else:
        assert re.search(r'-k\d$', name), name
        parent = FUSION
        keys = set() if name.endswith('7') else {'fusion.kernel_size'}
    assert model_delta(parent, path) == keys


@pytest.mark.parametrize('path', MAIN, ids=lambda p: osp.basename(p)[:-3])
def test_coupled_values_come_from_the_dataset_base(path):
    """The model's grid, classes and empty label are the dataset base's;
    Occ3D supervises the camera-visible voxels, as its metric counts
    them."""
    cfg = Config.fromfile(path)
    assert coupled_value_mismatches(cfg, 'sdg_occ') == []
    model = cfg.model
    assert model.type == 'SDGOcc'
    assert ('loss_distill' in model) is ('sdgocc-kl' in path)
    assert 'variant' not in model  # the sub-modules say it
    assert model.loss_depth.loss_weight == 0.05
    # The fusion's widths come from the detector, by variant.
    assert not {'source_channels', 'cross_channels',
                'out_channels'} & set(model.fusion)


def test_ablation_knobs():
    """Each ablation file sets the value its name says."""
    for path in ABLATIONS:
        name = osp.basename(path)
        model = Config.fromfile(path).model
        if match := re.search(r'-r(\d)l(\d+)_', name):
            assert model.view_transform.layer_radius == float(match[1])
            assert model.view_transform.num_layers == int(match[2])
        elif match := re.search(r'-k(\d)_', name):
            assert model.fusion.kernel_size == int(match[1])
        else:
            assert model.view_transform.use_sdg is ('-lss' not in name)
            assert model.get('num_frames', 1) == (2 if '-2f_' in name else 1)
            camera = '-camera-' in name
            assert (model.lidar_encoder is None) is camera
            assert (model.fusion is None) is camera
