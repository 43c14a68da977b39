#!/usr/bin/env python
"""How well a trained model's DepthNet places the LiDAR depths.

    python tools/analysis_tools/depth_accuracy.py CONFIG CHECKPOINT \\
        [--split train] \\
        [--data-root DIR] [--max-samples N] [--json OUT.json]

Runs the model's ``predict`` on the samples of a split through the config's
test pipeline (which draws the LiDAR depth maps) and compares the depth
distribution of the first DepthNet call of each step, the key frame's
views (the previous frames of a T-frame SDG-OCC come after it), with the
LiDAR: % of feature pixels whose most likely bin is right or at most one
bin off, the mean probability on the right bin, the mean distance from the
surface at which the feature mass lands, the mean entropy (see
:mod:`projects.occ_common.evaluation.depth_bin_accuracy`). ``--split
train`` measures the training scenes through the test pipeline, to tell an
underfitting DepthNet from one that does not generalise.
"""
import argparse
import json
from typing import Dict, Optional

import torch
from mmengine.config import DictAction

from projects.occ_common.apis.split_dataset import (add_split_arguments,
                                                    build_split_dataset)
from projects.occ_common.engine.config_checks import cfg_errors_exit


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('config', help='model config')
    parser.add_argument('checkpoint', help='trained weights')
    add_split_arguments(parser)
    parser.add_argument('--max-samples', type=int, default=None,
                        help='measure only the first N samples')
    parser.add_argument('--device', default='cpu')
    parser.add_argument(
        '--allow-key-mismatch', action='store_true',
        help="measure a checkpoint whose keys or shapes differ from the "
        "model's (missing ones keep their initialisation)")
    parser.add_argument('--json', default=None, help='write the numbers')
    parser.add_argument('--cfg-options', nargs='+', action=DictAction,
                        help='config overrides, as for tools/test.py')
    return parser.parse_args(argv)


def build(args):
    """The model with its weights and the dataset of ``args.split``.

    Returns:
        tuple: ``(model, dataset)``, the model in eval mode on
        ``args.device``.
    """
    from projects.occ_common.apis import init_model

    model = init_model(
        args.config, args.checkpoint, args.device, args.cfg_options,
        allow_key_mismatch=getattr(args, 'allow_key_mismatch', False))
    return model, build_split_dataset(model.cfg, args.split, args.data_root)


def measure(model, dataset, max_samples: Optional[int] = None
            ) -> Dict[str, float]:
    """Depth-bin statistics of ``model``'s DepthNet over ``dataset``.

    Args:
        model (nn.Module): An occupancy detector with ``depth_net``,
            ``depth_bound`` and ``gt_depth`` (both of this library's).
        dataset (Dataset): Samples with ``gt_depth`` maps.
        max_samples (int, optional): Only the first N. Defaults to all.

    Returns:
        dict[str, float]: :meth:`DepthBinAccuracy.summary` plus
        ``samples``.

    Raises:
        ValueError: If the model has no DepthNet, or a step never calls
            it (a camera-free variant).
    """
    from mmengine.dataset import pseudo_collate

    from projects.occ_common.evaluation import DepthBinAccuracy

    depth_net = getattr(model, 'depth_net', None)
    if depth_net is None:
        raise ValueError(f'{type(model).__name__} has no depth_net: it '
                         'lifts no image features by depth')
    captured = []

    def keep_first(module, inputs, output):
        if not captured:
            captured.append(output['depth'])

    accuracy = DepthBinAccuracy(model.depth_bound)
    count = len(dataset) if max_samples is None else min(
        max_samples, len(dataset))
    handle = depth_net.register_forward_hook(keep_first)
    try:
        for index in range(count):
            captured.clear()
            with torch.no_grad():
                data = model.data_preprocessor(
                    pseudo_collate([dataset[index]]), False)
                model(**data, mode='predict')
            if not captured:
                raise ValueError(f'sample {index}: {type(model).__name__} '
                                 'never called its depth_net')
            imgs = data['inputs']['imgs']
            gt_depth = model.gt_depth(data['data_samples'], imgs.device,
                                      tuple(imgs.shape[-2:]))
            accuracy.update(captured[0], gt_depth)
    finally:
        handle.remove()
    return dict(accuracy.summary(), samples=count)


def main(argv=None) -> Dict[str, float]:
    """Measure and print; returns the numbers."""
    args = parse_args(argv)
    model, dataset = build(args)
    out = measure(model, dataset, args.max_samples)
    print(f'{args.config} ({args.split}, {out["samples"]} samples, '
          f'{out["cells"]} feature pixels with a LiDAR depth):\n'
          f'  most likely bin right   {out["top1"]:6.2f} %\n'
          f'  ... or one bin off      {out["within_one_bin"]:6.2f} %\n'
          f'  probability on it       {out["prob_true"]:6.3f}\n'
          f'  mass-weighted distance  {out["expected_error_m"]:6.2f} m\n'
          f'  entropy                 {out["entropy"]:6.2f} nats '
          f'(uniform {out["uniform_entropy"]:.2f})')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(dict(out, config=args.config,
                           checkpoint=args.checkpoint, split=args.split),
                      f, indent=1)
    return out


if __name__ == '__main__':
    with cfg_errors_exit():
        main()
