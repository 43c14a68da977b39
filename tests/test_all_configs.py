"""Every config under configs/ loads and builds the model it always built.

Each config is built once: its model must match the fingerprint committed
in ``tests/data/config_fingerprints.json`` (parameter count, every
state-dict entry with its shape, the frozen parameters; see
:mod:`projects.occ_common.testing.config_fingerprint`), so a refactoring
of configs or model code cannot change a model unnoticed, and its metric
must build. A change that is *meant* to change a model (a new config, a
paper fix) regenerates the fixture in the same commit::

    python -m projects.occ_common.testing.config_fingerprint --write

(run it with the repository on ``PYTHONPATH``; without ``--write`` it
lists the configs that differ). The per-project config tests check the
coupled values; tests/test_docs_paths.py checks that the configs README.md
and docs/ name exist.
"""
import json
import os.path as osp

import pytest
from mmengine.config import Config

from projects.occ_common.testing.config_fingerprint import (FIXTURE,
                                                            build_model,
                                                            config_paths,
                                                            differences,
                                                            model_fingerprint)

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
CONFIGS = config_paths(ROOT)


@pytest.fixture(scope='module')
def fingerprints():
    with open(FIXTURE) as f:
        return json.load(f)


def test_every_project_has_configs():
    """Both models ship paper, ablation and tiny configs."""
    for project in ('occ_cyl', 'sdg_occ'):
        ours = [n for n in CONFIGS if n.startswith(f'configs/{project}/')]
        assert any('tiny' in n for n in ours), project
        assert any('/ablations/' in n for n in ours), project
        assert len(ours) >= 5, ours


def test_fixture_lists_every_config(fingerprints):
    """A config added or removed without regenerating the fixture fails."""
    assert sorted(fingerprints) == CONFIGS


@pytest.mark.parametrize('path', CONFIGS, ids=lambda p: p[len('configs/'):])
def test_config_builds_its_fingerprinted_model(path, fingerprints):
    """The model matches its fingerprint; the metric builds."""
    from mmdet3d.registry import METRICS
    model = build_model(osp.join(ROOT, path))
    assert differences(fingerprints[path], model_fingerprint(model)) == []
    cfg = Config.fromfile(osp.join(ROOT, path))
    assert 'projects.occ_common' in cfg.custom_imports['imports']
    if cfg.val_evaluator is None:  # the SPVCNN pre-training: no metric
        assert cfg.model.type == 'SPVCNNSegmentor'
        return
    evaluators = cfg.val_evaluator if isinstance(
        cfg.val_evaluator, list) else [cfg.val_evaluator]
    for evaluator in evaluators:
        assert METRICS.build(evaluator).default_prefix == 'occ'


@pytest.mark.parametrize('path', CONFIGS, ids=osp.basename)
def test_only_sdg_configs_read_lidarseg(path):
    """nuScenes-lidarseg is optional: OccCylindrical's configs never load
    it nor make 2-D semantic maps, except for training the seg2d variant,
    whose model has a 2-D semantic loss; SDG-OCC's make them (from
    lidarseg where the info has it, else from the occupancy labels). All
    drop the ego vehicle's returns. The SPVCNN lidarseg pre-training
    trains on nothing else: it requires the labels and has no test."""
    cfg = Config.fromfile(path)
    if cfg.model.type == 'SPVCNNSegmentor':
        steps = {t['type']: t for t in cfg.train_dataloader.dataset.pipeline}
        assert steps['LoadLidarSegLabels']['optional'] is False
        assert 'RemoveEgoPoints' in steps and cfg.test_dataloader is None
        return
    sdg = osp.basename(path).startswith('sdgocc')
    seg2d = cfg.model.get('loss_seg') is not None
    for loader, reads in ((cfg.train_dataloader, sdg or seg2d),
                          (cfg.test_dataloader, sdg)):
        steps = {t['type']: t for t in loader.dataset.pipeline}
        assert ('LoadLidarSegLabels' in steps) == reads
        assert ('PointsToSemanticMaps' in steps) == reads
        assert 'RemoveEgoPoints' in steps
        if reads:
            assert steps['LoadLidarSegLabels']['optional']


def _backbones_recomputed_with_training_norms(node, where='model'):
    """Paths of config dicts that recompute activations (``with_cp``)
    while their BatchNorms train (``norm_eval=False``): the recomputed
    forward of mmdet's backbones would update the running statistics a
    second time (RecomputedResNet restores them)."""
    found = []
    if isinstance(node, dict):
        if (node.get('with_cp') and node.get('norm_eval') is False
                and node.get('type') != 'RecomputedResNet'):
            found.append(where)
        for key, value in node.items():
            found += _backbones_recomputed_with_training_norms(
                value, f'{where}.{key}')
    elif isinstance(node, (list, tuple)):
        for i, value in enumerate(node):
            found += _backbones_recomputed_with_training_norms(
                value, f'{where}[{i}]')
    return found


@pytest.mark.parametrize('path', CONFIGS, ids=osp.basename)
def test_no_recomputation_with_training_batchnorm(path):
    """A backbone with ``norm_eval=False`` must not set ``with_cp``: the
    tiny OccCylindrical inherited the paper base's ``with_cp=True`` with
    its from-scratch ``norm_eval=False`` ResNet-18 and would have counted
    every BatchNorm update twice."""
    cfg = Config.fromfile(path)
    assert _backbones_recomputed_with_training_norms(cfg.model) == []
