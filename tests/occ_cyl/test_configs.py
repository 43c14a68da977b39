"""The OccCylindrical configs are deltas that state each fact once.

test_all_configs.py builds every config and compares its model with the
committed fingerprint; test_tiny_configs.py trains the tiny ones.
"""
import glob
import os.path as osp

import pytest
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope

from projects.occ_common.testing.config_delta import (coupled_value_mismatches,
                                                      model_delta)

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG_DIR = osp.join(ROOT, 'configs', 'occ_cyl')
MODEL_BASE = osp.join(CONFIG_DIR, '_base_', 'occcyl_r50-swint.py')
MAIN = sorted(glob.glob(osp.join(CONFIG_DIR, '*.py')))
ABLATIONS = sorted(glob.glob(osp.join(CONFIG_DIR, 'ablations', '*.py')))
PAPER = osp.join(CONFIG_DIR, 'occcyl_r50-swint_3xb1-24e_surroundocc-nus.py')
OCC3D = osp.join(CONFIG_DIR, 'occcyl_r50-swint_3xb1-24e_occ3d-nus.py')
TINY = osp.join(CONFIG_DIR, 'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')

#: What each config changes in the model of the config it builds on.
COUPLED = {'point_cloud_range', 'voxel_size', 'num_classes', 'empty_index'}
DELTAS = {
    # Dataset configs on the model base: the coupled values only.
    PAPER: (MODEL_BASE, COUPLED),
    OCC3D: (MODEL_BASE, COUPLED | {'loss_mask_key'}),
    # Table V (3), VI (2) and VII (3): one knob each.
    'occcyl-nodepthsup': (PAPER, {'loss_depth'}),
    'occcyl-nodepthfeat': (PAPER, {'depth_net.with_depth_feature'}),
    'occcyl-nopos': (PAPER, {'depth_net.position_channels'}),
    'occcyl-d2m': (PAPER, {'depth_bound'}),
    'occcyl-d10m': (PAPER, {'depth_bound'}),
    'occcyl-m1': (PAPER, {'tpv_fusion.num_groups'}),
    'occcyl-m2': (PAPER, {'tpv_fusion.num_groups'}),
    'occcyl-m4': (PAPER, {'tpv_fusion.num_groups'}),
}


def _name(path):
    return osp.basename(path).split('_')[0] if '/ablations/' in path else path


def test_config_inventory():
    """The paper's config, its Occ3D variant, the tiny synthetic config and
    the deltas of Tables V (3 files), VI (2) and VII (3)."""
    assert set(MAIN) == {PAPER, OCC3D, TINY}
    assert {_name(p) for p in ABLATIONS} | {PAPER, OCC3D} == set(DELTAS)


@pytest.mark.parametrize(
    'path', [PAPER, OCC3D] + ABLATIONS, ids=lambda p: osp.basename(p)[:-3])
def test_each_delta_changes_only_its_documented_keys(path):
    """Compared with the config it builds on, a config changes exactly the
    model keys listed in DELTAS."""
    parent, keys = DELTAS[_name(path)]
    assert model_delta(parent, path) == keys


@pytest.mark.parametrize('path', MAIN, ids=lambda p: osp.basename(p)[:-3])
def test_coupled_values_come_from_the_dataset_base(path):
    """The model's grid, classes and empty label are the dataset base's
    (Occ3D: 'free' = 17 and the camera-mask loss, as the metric), the
    config needs both packages, and the images are the paper's size."""
    cfg = Config.fromfile(path)
    assert coupled_value_mismatches(cfg, 'occ_cyl') == []
    aug = [t for t in cfg.train_pipeline if t.type == 'MultiViewImageAug']
    assert aug[0].final_size == cfg.img_size


def test_ablation_knobs():
    """Table VI: (1, 51, d) gives 25 bins at d = 2 and 5 at d = 10; Table
    VII: M = 1, 2, 4."""
    for path in ABLATIONS:
        name, model = _name(path), Config.fromfile(path).model
        if name.startswith('occcyl-d'):
            step = float(name[len('occcyl-d'):-1])
            assert model.depth_bound == [1.0, 51.0, step]
        if name.startswith('occcyl-m'):
            assert model.tpv_fusion.num_groups == int(name[-1])


def test_paper_model_parameter_count(capsys):
    """The paper config builds a ResNet-50 image backbone: 23,508,032
    parameters (torchvision's 25,557,032 minus the 2048 x 1000 + 1000 fc).
    The total is printed for the report, next to the paper's 111.62 M."""
    cfg = Config.fromfile(PAPER)
    init_default_scope(cfg.default_scope)
    model = MODELS.build(cfg.model)
    backbone = sum(p.numel() for p in model.img_encoder.backbone.parameters())
    assert backbone == 25_557_032 - (2048 * 1000 + 1000)
    parts = {
        name: sum(p.numel() for p in child.parameters())
        for name, child in model.named_children()
    }
    total = sum(p.numel() for p in model.parameters())
    assert total == sum(parts.values())
    with capsys.disabled():
        print(f'\nOccCylindrical paper config: {total / 1e6:.2f} M '
              f'parameters (paper: 111.62 M); ' +
              ', '.join(f'{k} {v / 1e6:.2f} M' for k, v in parts.items() if v))
