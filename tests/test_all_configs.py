"""Every config under configs/ loads and builds its model and evaluator.

The per-project config tests check coupled values; this one guarantees that
no config can drift from the code (a renamed argument, a missing import)
and that the README's configs exist.
"""
import glob
import os.path as osp
import re

import pytest
from mmengine.config import Config

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
CONFIGS = sorted(
    p for p in glob.glob(osp.join(ROOT, 'configs', '**', '*.py'),
                         recursive=True) if '_base_' not in p)


def test_every_project_has_configs():
    """Both models ship paper, ablation and tiny configs."""
    names = [osp.relpath(p, ROOT) for p in CONFIGS]
    for project in ('occ_cyl', 'sdg_occ'):
        ours = [n for n in names if n.startswith(f'configs/{project}/')]
        assert any('tiny' in n for n in ours), project
        assert any('/ablations/' in n for n in ours), project
        assert len(ours) >= 5, ours


@pytest.mark.parametrize(
    'path', CONFIGS, ids=lambda p: osp.relpath(p, ROOT)[len('configs/'):])
def test_config_builds_model_and_evaluator(path):
    """The model and the metric build from the config, with its imports."""
    from mmdet3d.registry import METRICS, MODELS
    from mmdet3d.utils import register_all_modules
    register_all_modules()  # as the Runner does for default_scope mmdet3d
    cfg = Config.fromfile(path)
    assert 'projects.occ_common' in cfg.custom_imports['imports']
    model = MODELS.build(cfg.model)
    assert sum(p.numel() for p in model.parameters()) > 0
    metric = METRICS.build(cfg.val_evaluator)
    assert metric.default_prefix == 'occ'


def test_readme_names_only_existing_configs():
    """Each ``configs/...py`` path in the README exists."""
    with open(osp.join(ROOT, 'README.md')) as f:
        readme = f.read()
    paths = set(re.findall(r'configs/[\w/.-]+\.py', readme))
    missing = [p for p in paths if not osp.isfile(osp.join(ROOT, p))]
    assert missing == []
