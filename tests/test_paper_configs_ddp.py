"""Every paper config's model trains under DDP (2 gloo ranks, 2 steps).

A paper model at its own size costs minutes a step on the CPU, so each
config is trained as its *narrow twin*: the same config with every channel
width cut (8-channel ResNet stem, 16-32 channel planes and BEVs), small
images, 2,000 points and a coarser cylinder / depth bins. Widths and
resolutions change parameter shapes, never which parameters exist or
take part in the loss; the twin must have exactly the paper model's
parameters (names and ``requires_grad``), which the first test checks.
The configs then fall into a few distinct graphs, and one config of each
is trained under mmengine's DDP wrapper with ``find_unused_parameters``
left False, as ``tools/dist_train.sh`` does.

On the code before issue 45 the SDG configs failed here: their
``mmdet.FPN`` built a 1/32 output convolution SDG never reads
(``img_neck.fpn_convs.1.conv.weight`` and ``.bias`` got no gradient in
the first step) and DDP raised "Expected to have finished reduction in the
prior iteration" at the second.
"""
import math
import os.path as osp
from typing import Dict, List, Tuple

import pytest
from mmengine.config import Config

from projects.occ_common.testing.config_fingerprint import config_paths

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
#: Configs of the papers' models and ablations (not the synthetic ones).
PAPER_CONFIGS = [p for p in config_paths(ROOT) if 'synthetic' not in p]


def _resnet_widths(backbone: dict, base: int) -> List[int]:
    """Output channels of a ResNet-50's stages ``out_indices`` with
    ``base_channels=base`` (bottleneck expansion 4, doubling a stage)."""
    return [base * 4 * 2**i for i in backbone['out_indices']]


def narrow_options(cfg: Config) -> Dict:
    """Overrides that make the config's model small but keep its modules.

    Returns:
        dict: ``Config.merge_from_dict`` keys.
    """
    model = cfg.model
    if model.type == 'OccCylindrical':
        opts = {
            'img_size': (96, 160),
            'model.depth_bound': [1.0, 51.0, 5.0],
            'model.cylinder.shape': [32, 64, 16],
            'model.pretrained.img_backbone.checkpoint': None,
            'model.pretrained.tpv_backbone.checkpoint': None,
            'model.img_encoder.backbone.base_channels': 8,
            'model.img_encoder.neck.in_channels': _resnet_widths(
                model.img_encoder.backbone, 8),
            'model.img_encoder.neck.out_channels': 16,
            'model.img_encoder.neck_channels': 16,
            'model.img_encoder.out_channels': 32,
            'model.depth_net.in_channels': 32,
            'model.depth_net.mid_channels': 32,
            'model.depth_net.context_channels': 8,
            'model.point_branch.img_channels': 8,
            'model.point_branch.geo_channels': [8] * len(
                model.point_branch.geo_channels),
            'model.point_branch.out_channels': [8] * len(
                model.point_branch.out_channels),
            'model.tpv_fusion.cam_channels': 8,
            'model.tpv_fusion.lidar_channels': 8,
            'model.tpv_fusion.plane_channels': 16,
            'model.tpv_encoder.backbone.in_channels': 16,
            # 24, 48, 96, 192 channels: 8 per head of Swin-S's 3-24 heads.
            'model.tpv_encoder.backbone.embed_dims': 24,
            'model.tpv_encoder.neck.in_channels': [24, 48, 96, 192],
            'model.tpv_encoder.neck.out_channels': 16,
            'model.occ_head.in_channels': 16,
            'model.occ_head.hidden_channels': 16,
        }
    elif model.type == 'SDGOcc':
        opts = {
            # Multiples of 32 (pad_size_divisor): the depth targets match.
            'img_size': (64, 192),
            'model.depth_bound': [1.0, 45.0, 1.0],
            'model.pretrained': None,
            'model.img_backbone.base_channels': 8,
            'model.img_neck.in_channels': _resnet_widths(
                model.img_backbone, 8),
            'model.img_neck.out_channels': 32,
            'model.depth_net.in_channels': 32,
            'model.depth_net.mid_channels': 32,
            'model.depth_net.context_channels': 16,
            'model.bev_encoder.in_channels': 16,
            'model.bev_encoder.stage_channels': [32, 64, 128],
            'model.bev_encoder.out_channels': 32,
            'model.occ_head.in_channels': 32,
            'model.occ_head.mid_channels': 32,
        }
        if model.get('lidar_encoder'):
            opts.update({
                'model.lidar_encoder.base_channels': 8,
                'model.lidar_encoder.stage_channels': [16, 16],
                'model.lidar_encoder.out_channels': 16,
            })
        if model.get('fusion'):
            opts.update({
                'model.fusion.embed_dims': 16,
                'model.fusion.num_heads': 2
            })
    elif model.type == 'SPVCNNSegmentor':  # the lidarseg pre-training
        opts = {
            'model.lidar_encoder.base_channels': 8,
            'model.lidar_encoder.stage_channels': [16, 16],
        }
    else:
        raise AssertionError(f'no narrow twin for {model.type}')
    return opts


def _graph(model) -> Tuple[Tuple[str, bool], ...]:
    return tuple((n, p.requires_grad) for n, p in model.named_parameters())


_GRAPHS: Dict[str, tuple] = {}


def _build(path: str, options=None):
    from mmdet3d.registry import MODELS
    from mmengine.registry import init_default_scope
    cfg = Config.fromfile(osp.join(ROOT, path))
    if options:
        cfg.merge_from_dict(options)
    init_default_scope('mmdet3d')
    return cfg, MODELS.build(cfg.model)


@pytest.mark.parametrize('path', PAPER_CONFIGS,
                         ids=lambda p: p[len('configs/'):])
def test_narrow_twin_has_the_paper_models_parameters(path):
    """Same parameter names in the same order, same ``requires_grad``."""
    cfg, paper = _build(path)
    _, twin = _build(path, narrow_options(cfg))
    graph = _graph(paper)
    assert _graph(twin) == graph
    # Narrow: a step costs seconds, not minutes.
    assert sum(p.numel() for p in twin.parameters()) < 0.1 * sum(
        p.numel() for p in paper.parameters())
    _GRAPHS[path] = graph


@pytest.mark.slow
def test_every_paper_graph_trains_two_ddp_steps():
    """One config per distinct graph, 2 gloo ranks x 2 steps, a different
    random batch per rank.

    Each rank: every trainable parameter got a gradient in step 1 (none
    ``unused``), both losses finite, and after step 2 every parameter
    equals rank 0's exactly (0.0): DDP averaged the two ranks' gradients,
    whose losses differ.
    """
    from projects.occ_common.analysis.ddp_check import ddp_check
    if len(_GRAPHS) != len(PAPER_CONFIGS):
        for path in PAPER_CONFIGS:
            cfg, model = _build(path)
            _GRAPHS[path] = _graph(model)
    groups: Dict[tuple, List[str]] = {}
    for path in PAPER_CONFIGS:
        groups.setdefault(_GRAPHS[path], []).append(path)
    jobs = []
    for paths in groups.values():
        path = paths[0]
        cfg = Config.fromfile(osp.join(ROOT, path))
        jobs.append(
            dict(config=osp.join(ROOT, path), options=narrow_options(cfg),
                 batch_size=1))
    results = ddp_check(jobs, ranks=2, iters=2, num_points=2000,
                        timeout_s=300)
    assert len(results) == len(groups)
    for job, ranks in zip(jobs, results):
        name = osp.relpath(job['config'], ROOT)
        for result in ranks:
            assert result['error'] is None, (name, result.get('traceback'))
            assert result['backend'] == 'gloo'
            assert result['unused'] == [], name
            assert len(result['losses']) == 2
            assert all(math.isfinite(v) for v in result['losses']), name
            assert result['max_param_diff_from_rank0'] == 0.0, name
        assert ranks[0]['losses'][0] != ranks[1]['losses'][0], name
