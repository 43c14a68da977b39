"""Benchmark an OccCylindrical config's multi-scale occupancy loss, against
the loss code of another git revision.

The loss (focal, Lovasz-softmax and the two SCAL terms at every scale of
the head, eq. 18) took most of a CPU training iteration of the small
OccCylindrical until the faster losses of 2026-11-27 (83bfedd). This tool
builds the config's head, draws labels and logits of the head's scale
shapes, and times the loss's forward + backward. With ``--ref REV`` it
also loads ``projects/occ_common/models/losses`` as it was at REV (``git
show``, into a temporary package; its registrations are kept out of the
registry except while the reference loss is built) and times both in
alternating rounds (:func:`alternating_runs`; ``OMP_NUM_THREADS`` sets the
threads), printing the medians and the largest relative difference of
their loss terms and logit gradients. The reference is this repository's
own code, run as it was committed.

The inputs imitate a trained model: each voxel is empty with probability
``--empty`` (about the share of empty voxels in the synthetic world's
SurroundOcc labels), else of a uniformly drawn class, and its logits are
``--confidence`` on its class plus unit-normal noise, so that most voxels
are right and some are confidently wrong (which decides how many errors
the Lovasz sort sees). The labels are down-sampled per scale by the loss
itself, as in training.

Example::

    OMP_NUM_THREADS=1 python tools/analysis_tools/benchmark_occ_loss.py \
        configs/occ_cyl/occcyl_small_1xb1-12e_surroundocc-nus-synthetic.py \
        --ref 8d28a04 --rounds 7
"""
import argparse
import contextlib
import importlib.util
import json
import os
import os.path as osp
import subprocess
import sys
import tempfile
from typing import Callable, Dict, List, Tuple

import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import Registry, init_default_scope
from mmengine.utils import import_modules_from_strings
from torch import nn

from projects.occ_common.analysis.benchmarking import (alternating_runs,
                                                       round_medians)

ROOT = osp.dirname(
    osp.dirname(osp.dirname(osp.abspath(__file__))))
#: The package whose revisions are compared.
LOSSES = 'projects/occ_common/models/losses'


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('config', help='an OccCylindrical config')
    parser.add_argument('--ref', help='git revision whose loss code to '
                        'time against the working tree\'s')
    parser.add_argument('--rounds', type=int, default=7, help='timed rounds')
    parser.add_argument('--batch', type=int, default=1, help='samples')
    parser.add_argument('--empty', type=float, default=0.9,
                        help='share of empty voxels')
    parser.add_argument('--confidence', type=float, default=4.0,
                        help='logit margin of the true class')
    parser.add_argument('--out', help='write the results as JSON here')
    return parser.parse_args(argv)


def build_head(cfg: Config) -> nn.Module:
    """The occupancy head of the config's model, with its loss (current
    code; the model hands the head its cylinder and grid)."""
    if cfg.get('custom_imports'):
        import_modules_from_strings(**cfg.custom_imports)
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    head_cfg = cfg.model.get('occ_head')
    if head_cfg is None or 'loss_occ' not in head_cfg:
        raise ValueError('benchmark_occ_loss: expected a config whose '
                         'model.occ_head has a loss_occ (OccCylindrical).')
    torch.manual_seed(0)
    return MODELS.build(cfg.model).occ_head


def draw_inputs(scale_shapes: List[Tuple[int, int, int]], num_classes: int,
                batch: int, empty: float, confidence: float,
                empty_index: int) -> Tuple[List[torch.Tensor], torch.Tensor]:
    """Logits of every scale and the full-resolution labels.

    Args:
        scale_shapes (list[tuple[int, int, int]]): (X, Y, Z) per scale,
            finest first.
        num_classes (int): C, empty included.
        batch (int): B.
        empty (float): Probability that a voxel is empty.
        confidence (float): Margin added to the true class's logit.
        empty_index (int): Label of empty space.

    Returns:
        tuple[list[Tensor], Tensor]: Logits, scale l of Shape
        (B, C, X_l, Y_l, Z_l), leaves without gradient; labels Shape
        (B, X_0, Y_0, Z_0).
    """
    gen = torch.Generator().manual_seed(0)
    full = (batch, *scale_shapes[0])
    others = [c for c in range(num_classes) if c != empty_index]
    drawn = torch.tensor(others)[torch.randint(
        len(others), full, generator=gen)]
    labels = torch.where(torch.rand(full, generator=gen) < empty,
                         torch.full_like(drawn, empty_index), drawn)
    logits = []
    for level, shape in enumerate(scale_shapes):
        factor = 2**level
        coarse = labels[:, ::factor, ::factor, ::factor]
        noise = torch.randn(batch, num_classes, *shape, generator=gen)
        margin = torch.zeros_like(noise).scatter_(1, coarse.unsqueeze(1),
                                                  confidence)
        logits.append(noise + margin)
    return logits, labels


@contextlib.contextmanager
def _forced_registration(registry: Registry):
    """Within the block, registering a taken name replaces its class."""
    original = registry._register_module

    def forced(module, module_name=None, force=False):
        original(module=module, module_name=module_name, force=True)

    registry._register_module = forced
    try:
        yield
    finally:
        del registry._register_module


def load_reference(rev: str, registry: Registry = MODELS):
    """Import the loss package as it was at ``rev``.

    Its files are written to a temporary folder and imported as
    ``projects.occ_common.models._losses_at_<rev>`` (so that its relative
    imports of the rest of the project resolve); the classes it registers
    are taken out of ``registry`` again and returned.

    Args:
        rev (str): A git revision of this repository.
        registry (Registry): Where the package registers its losses.

    Returns:
        dict[str, type]: Registered name -> the class at ``rev``.

    Raises:
        ValueError: If ``rev`` has no loss package.
    """
    listing = subprocess.run(
        ['git', 'ls-tree', '--name-only', rev, LOSSES + '/'], cwd=ROOT,
        capture_output=True, text=True)
    files = [f for f in listing.stdout.split() if f.endswith('.py')]
    if listing.returncode or not files:
        raise ValueError(f'benchmark_occ_loss: no {LOSSES} at revision '
                         f'{rev!r}: {listing.stderr.strip()}')
    name = ('projects.occ_common.models._losses_at_'
            + ''.join(c if c.isalnum() else '_' for c in rev))
    saved = dict(registry._module_dict)
    # The files are read only while the package is imported.
    with tempfile.TemporaryDirectory(prefix='losses_at_') as folder:
        for path in files:
            text = subprocess.run(['git', 'show', f'{rev}:{path}'],
                                  cwd=ROOT, capture_output=True, text=True,
                                  check=True)
            with open(osp.join(folder, osp.basename(path)), 'w') as f:
                f.write(text.stdout)
        spec = importlib.util.spec_from_file_location(
            name, osp.join(folder, '__init__.py'),
            submodule_search_locations=[folder])
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            with _forced_registration(registry):
                spec.loader.exec_module(module)
            return {
                key: cls
                for key, cls in registry._module_dict.items()
                if saved.get(key) is not cls
            }
        finally:
            registry._module_dict.clear()
            registry._module_dict.update(saved)


@contextlib.contextmanager
def registered(classes: Dict[str, type], registry: Registry = MODELS):
    """Within the block, ``registry`` builds ``classes`` by their names."""
    saved = dict(registry._module_dict)
    registry._module_dict.update(classes)
    try:
        yield
    finally:
        registry._module_dict.clear()
        registry._module_dict.update(saved)


def build_loss_like(head: nn.Module, loss_cfg: dict) -> nn.Module:
    """Build ``loss_cfg`` with the arguments the head gave its own loss."""
    own = head.loss_occ
    return MODELS.build(
        loss_cfg,
        default_args=dict(
            num_scales=own.num_scales,
            empty_index=own.empty_index,
            ignore_index=own.ignore_index))


def loss_and_grads(loss: nn.Module, logits: List[torch.Tensor],
                   labels: torch.Tensor
                   ) -> Tuple[Dict[str, float], List[torch.Tensor]]:
    """The loss terms and the gradient of their sum on every scale."""
    leaves = [x.clone().requires_grad_() for x in logits]
    terms = loss(leaves, labels)
    sum(terms.values()).backward()
    return ({k: float(v.detach()) for k, v in terms.items()},
            [x.grad for x in leaves])


def relative_difference(a: torch.Tensor, b: torch.Tensor) -> float:
    """``max |a - b| / max |b|`` (0 when both are 0)."""
    scale = float(b.abs().max())
    return float((a - b).abs().max()) / scale if scale > 0 else float(
        (a - b).abs().max())


def step(loss: nn.Module, logits: List[torch.Tensor],
         labels: torch.Tensor) -> Callable[[], None]:
    """One timed forward + backward of ``loss``."""
    leaves = [x.clone().requires_grad_() for x in logits]

    def run():
        sum(loss(leaves, labels).values()).backward()
        for x in leaves:
            x.grad = None

    return run


def measure(head: nn.Module, loss_cfg: dict, args) -> dict:
    """Time the head's loss (and the reference's, with ``--ref``).

    Returns:
        dict: ``current`` (and ``ref``) -> medians ``wall_s``, ``cpu_s``
        and the per-round times; ``terms``: the current loss terms;
        with ``--ref``, ``max_term_rel_diff`` and ``max_grad_rel_diff``;
        ``voxels``: finest-scale voxels per sample.
    """
    logits, labels = draw_inputs(head.scale_shapes, head.num_classes,
                                 args.batch, args.empty, args.confidence,
                                 head.loss_occ.empty_index)
    losses = dict(current=head.loss_occ)
    if args.ref:
        with registered(load_reference(args.ref)):
            losses['ref'] = build_loss_like(head, loss_cfg)
    result = dict(voxels=int(torch.Size(head.scale_shapes[0]).numel()))
    terms, grads = loss_and_grads(losses['current'], logits, labels)
    result['terms'] = terms
    if args.ref:
        ref_terms, ref_grads = loss_and_grads(losses['ref'], logits, labels)
        if set(ref_terms) != set(terms):
            raise ValueError(
                f'benchmark_occ_loss: the loss at {args.ref} gives the '
                f'terms {sorted(ref_terms)}, the current one '
                f'{sorted(terms)}.')
        result['max_term_rel_diff'] = max(
            abs(terms[k] - ref_terms[k]) / max(abs(ref_terms[k]), 1e-12)
            for k in terms)
        result['max_grad_rel_diff'] = max(
            relative_difference(a, b) for a, b in zip(grads, ref_grads))
    result.update(
        round_medians(
            alternating_runs(
                {name: step(loss, logits, labels)
                 for name, loss in losses.items()},
                args.rounds,
                warmup=1)))
    return result


def main(argv=None):
    """Run the benchmark and print its medians."""
    args = parse_args(argv)
    cfg = Config.fromfile(args.config)
    head = build_head(cfg).train()
    result = measure(head, cfg.model.occ_head.loss_occ, args)
    line = (f'{result["voxels"]:,} voxels at the finest of '
            f'{len(head.scale_shapes)} scales, batch {args.batch}, forward '
            f'+ backward, median of {args.rounds} rounds: current '
            f'{result["current"]["wall_s"]:.3f} s wall / '
            f'{result["current"]["cpu_s"]:.3f} s CPU')
    if args.ref:
        line += (f'; {args.ref} {result["ref"]["wall_s"]:.3f} s / '
                 f'{result["ref"]["cpu_s"]:.3f} s (alternating rounds); '
                 f'largest relative difference: terms '
                 f'{result["max_term_rel_diff"]:.1e}, gradients '
                 f'{result["max_grad_rel_diff"]:.1e}')
    print(line)
    if args.out:
        os.makedirs(osp.dirname(osp.abspath(args.out)), exist_ok=True)
        with open(args.out, 'w') as f:
            json.dump(dict(config=args.config, ref=args.ref, result=result),
                      f, indent=2)
    return result


if __name__ == '__main__':
    main()
