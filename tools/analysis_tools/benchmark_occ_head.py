"""Benchmark the OccCylindrical head: project then sample, or the old order.

``CylindricalOccHead`` applies its MLP's first (linear) layer to each TPV
plane before it samples the planes at the voxels (eq. 17's weighted sum
commutes with a linear map); the order of before sampled the three planes
at every voxel, summed them and ran the whole MLP there. This tool builds
the head of an OccCylindrical config (its cylinder, occupancy grid, plane
width and MLP width; ``--hidden`` overrides the MLP width), feeds it random
planes of the sizes the config's TPV encoder gives at each level, and times
forward + backward (a squared-logit loss) of both orders in alternating
rounds (:func:`alternating_runs`), with the config's ``with_cp``. It
reports the medians of wall and process CPU time, and the largest logit
difference between the two orders (float rounding only).

Example::

    OMP_NUM_THREADS=1 python tools/analysis_tools/benchmark_occ_head.py \
        configs/occ_cyl/occcyl_small_1xb1-12e_surroundocc-nus-synthetic.py \
        --hidden 32 128 --rounds 7
"""
import argparse
import contextlib
import json
import types
from typing import Dict, List, Optional, Tuple

import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope
from mmengine.utils import import_modules_from_strings
from torch import Tensor

from projects.occ_common.analysis.benchmarking import (alternating_runs,
                                                       round_medians)
from projects.occ_cyl.cylindrical_occ_head import sample_tpv_planes
from projects.occ_cyl.group_pooling import PLANE_POOL_AXES


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('config', help='an OccCylindrical config')
    parser.add_argument(
        '--hidden', type=int, nargs='+', default=None,
        help='MLP widths to measure (default: the config\'s)')
    parser.add_argument('--rounds', type=int, default=7, help='timed rounds')
    parser.add_argument('--batch', type=int, default=1, help='samples')
    parser.add_argument('--threads', type=int, default=0,
                        help='torch CPU threads (0: keep)')
    parser.add_argument('--out', help='write the results as JSON here')
    return parser.parse_args(argv)


def classify_the_sum(head, level: int, *planes: Tensor) -> Tensor:
    """The head's order before the projection moved ahead of sampling:
    sample the three planes at every voxel, sum, run the whole MLP.

    Returns:
        Tensor: Shape (B, num_classes, X_l, Y_l, Z_l).
    """
    feats = sample_tpv_planes(planes, getattr(head, f'columns_{level}'),
                              getattr(head, f'heights_{level}'), head.wrap)
    out = head.classifiers[level](feats)
    return out.transpose(1, 2).reshape(out.shape[0], head.num_classes,
                                       *head.scale_shapes[level])


def build_model(cfg: Config, hidden: Optional[int]):
    """The config's OccCylindrical, its head's MLP ``hidden`` wide."""
    if cfg.get('custom_imports'):
        import_modules_from_strings(**cfg.custom_imports)
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    model_cfg = cfg.model.copy()
    if hidden is not None:
        model_cfg.occ_head = dict(model_cfg.occ_head, hidden_channels=hidden)
    torch.manual_seed(0)
    return MODELS.build(model_cfg).train()


def plane_shapes(model) -> List[List[Tuple[int, int]]]:
    """Per level, the (R, Theta), (Theta, Z), (R, Z) plane sizes that the
    model's TPV encoder outputs (the cylinder's sides over the level's
    stride)."""
    sides = model.cylinder.shape
    return [[
        tuple(sides[a - 1] // stride for a in kept)
        for _, kept in PLANE_POOL_AXES
    ] for stride in model.tpv_encoder.level_strides]


def random_planes(model, batch: int) -> List[Tuple[Tensor, ...]]:
    """Unit-normal planes of the head's width, requiring gradients."""
    gen = torch.Generator().manual_seed(0)
    channels = model.occ_head.classifiers[0][0].in_features
    return [
        tuple(
            torch.randn(batch, channels, *hw, generator=gen).requires_grad_()
            for hw in level) for level in plane_shapes(model)
    ]


@contextlib.contextmanager
def old_order(head):
    """Within the block, ``head`` runs :func:`classify_the_sum` in place of
    its own ``_scale_logits`` (an instance attribute shadows the method;
    a checkpointed backward recomputes with the function it was given)."""
    head._scale_logits = types.MethodType(classify_the_sum, head)
    try:
        yield head
    finally:
        del head._scale_logits


def measure(model, planes, rounds: int) -> Dict[str, dict]:
    """Time both orders of ``model.occ_head`` in alternating rounds.

    Returns:
        dict: ``projected`` and ``summed`` -> medians ``wall_s``, ``cpu_s``
        and the per-round times; ``max_abs_diff``: the largest logit
        difference of the two orders; ``voxels``: finest-scale voxels.
    """
    head = model.occ_head
    grads = list(head.parameters()) + [p for lvl in planes for p in lvl]

    def step(old: bool):

        def run():
            with old_order(head) if old else contextlib.nullcontext():
                logits = head(planes)
            sum(x.square().mean() for x in logits).backward()
            for param in grads:
                param.grad = None

        return run

    calls = dict(projected=step(False), summed=step(True))
    with torch.no_grad():
        projected = head(planes)
        with old_order(head):
            summed = head(planes)
    diff = max((a - b).abs().max().item()
               for a, b in zip(projected, summed))
    result = round_medians(alternating_runs(calls, rounds, warmup=1))
    result['max_abs_diff'] = diff
    result['voxels'] = int(torch.Size(head.scale_shapes[0]).numel())
    return result


def main(argv=None):
    """Run the benchmark and print one line per MLP width."""
    args = parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    cfg = Config.fromfile(args.config)
    widths = args.hidden or [cfg.model.occ_head.hidden_channels]
    rows = []
    for hidden in widths:
        model = build_model(cfg, hidden)
        result = measure(model, random_planes(model, args.batch),
                         args.rounds)
        result['hidden'] = hidden
        rows.append(result)
        print(f'hidden {hidden}, {result["voxels"]:,} voxels, forward + '
              f'backward, median of {args.rounds} alternating rounds: '
              f'projected {result["projected"]["wall_s"]:.3f} s wall / '
              f'{result["projected"]["cpu_s"]:.3f} s CPU, summed '
              f'{result["summed"]["wall_s"]:.3f} s / '
              f'{result["summed"]["cpu_s"]:.3f} s; largest logit '
              f'difference {result["max_abs_diff"]:.2e}')
    if args.out:
        with open(args.out, 'w') as f:
            json.dump(dict(config=args.config, rows=rows), f, indent=2)
    return rows


if __name__ == '__main__':
    main()
