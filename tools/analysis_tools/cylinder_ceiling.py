#!/usr/bin/env python
"""How much of a split's ground truth can a cylinder hold? Per class.

    python tools/analysis_tools/cylinder_ceiling.py CONFIG [--shapes \\
        64x128x16 ...] \\
        [--split train] [--data-root DIR] [--json OUT.json]

OccCylindrical predicts from features on a cylinder of ``(R, Theta, Z)``
cells (``model.cylinder``) and samples them back at the Cartesian voxel
centres. This tool replaces every ground-truth voxel of a split by the
majority class of the cylinder cell its centre falls in (unlabelled voxels
do not vote; ties go to the lower label) and scores that against the
ground truth with the metric's rules: the IoU / mIoU a model would reach
if each cell could hold one class. A coarse cylinder merges a far
pedestrian with the road around it; the score shows, per class, what a
shape costs before any learning (2026-11-27, ad94fac: the small config's
64 x 128 x 16 cells keep 69.3 mIoU of the held-out synthetic scenes, 128 x
256 x 16 keep 89.5). Without ``--shapes`` the config's own cylinder is
measured; each shape is given as ``RxThetaxZ`` and keeps the config's
radius fit and clamping. The model samples its planes by linear
interpolation, so a trained model is not strictly bounded by this
nearest-cell score, but a class far under it cannot be blamed on the
cylinder.
"""
import argparse
import json
from typing import Dict, List, Sequence, Tuple

import numpy as np
import torch
from mmengine.config import Config

from projects.occ_common.apis.split_dataset import (add_split_arguments,
                                                    labelled_samples,
                                                    load_tool_config)
from projects.occ_common.engine.config_checks import (CfgOptionsAction,
                                                      cfg_errors_exit)
from projects.occ_common.evaluation import OccupancyMetric
from projects.occ_common.visualization.camera_overlay import voxel_centres
from projects.occ_cyl.cylindrical import CylinderGrid, cartesian_to_cylindrical


def parse_shape(text: str) -> Tuple[int, int, int]:
    """``'64x128x16'`` -> ``(64, 128, 16)``."""
    parts = text.lower().split('x')
    if len(parts) != 3 or not all(p.isdigit() and int(p) > 0 for p in parts):
        raise argparse.ArgumentTypeError(
            f'expected a cylinder shape RxThetaxZ of positive integers, e.g.'
            f' 64x128x16, got {text!r}')
    return tuple(int(p) for p in parts)


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('config', help='an OccCylindrical config')
    parser.add_argument(
        '--shapes',
        nargs='+',
        type=parse_shape,
        default=None,
        metavar='RxTxZ',
        help='cylinder shapes (default: the config\'s)')
    add_split_arguments(parser)
    parser.add_argument('--json', default=None, help='write the numbers')
    parser.add_argument(
        '--cfg-options',
        nargs='+',
        action=CfgOptionsAction,
        help='config overrides, as for tools/test.py')
    return parser.parse_args(argv)


def cell_of_voxels(grid_shape: Sequence[int], pc_range: Sequence[float],
                   voxel_size: Sequence[float],
                   cylinder: CylinderGrid) -> np.ndarray:
    """The cylinder cell of every Cartesian voxel centre.

    Args:
        grid_shape (Sequence[int]): ``(X, Y, Z)``.
        pc_range (Sequence[float]): ``(x0, y0, z0, x1, y1, z1)``.
        voxel_size (Sequence[float]): ``(dx, dy, dz)``.
        cylinder (CylinderGrid): The cells.

    Returns:
        np.ndarray: int64 flat cell index, -1 where the centre lies in no
        cell (a cylinder without clamping). Shape (X, Y, Z).
    """
    index = np.stack(
        np.meshgrid(*[np.arange(n) for n in grid_shape], indexing='ij'),
        axis=-1)
    centres = torch.from_numpy(voxel_centres(index, pc_range, voxel_size))
    cells = cylinder.flat_index(cartesian_to_cylindrical(centres))
    return cells.numpy()


def majority_labels(occ: np.ndarray, cells: np.ndarray, num_cells: int,
                    num_classes: int, ignore_index: int,
                    fill: int) -> np.ndarray:
    """Each voxel's label replaced by its cell's majority label.

    Args:
        occ (np.ndarray): Labels in ``[0, num_classes)`` or
            ``ignore_index``. Shape (X, Y, Z).
        cells (np.ndarray): Each voxel's cell, -1 for none. Shape (X, Y, Z).
        num_cells (int): Number of cells.
        num_classes (int): C.
        ignore_index (int): The label that does not vote.
        fill (int): Label of voxels in no cell, or in a cell without a
            labelled voxel (the empty / free class).

    Returns:
        np.ndarray: int64 labels. Shape (X, Y, Z).
    """
    labels = np.asarray(occ, np.int64).ravel()
    cell = np.asarray(cells, np.int64).ravel()
    votes = (labels != ignore_index) & (cell >= 0)
    counts = np.bincount(
        cell[votes] * num_classes + labels[votes],
        minlength=num_cells * num_classes).reshape(num_cells, num_classes)
    # argmax takes the first of equal counts: ties go to the lower label.
    major = np.where(counts.any(1), counts.argmax(1), fill)
    out = np.where(cell >= 0, major[np.maximum(cell, 0)], fill)
    return out.reshape(np.shape(occ))


def _cylinders(cfg: Config,
               shapes: Sequence[Tuple[int, int, int]]) -> List[CylinderGrid]:
    """One grid per shape, fitted as the config's model fits its own."""
    spec = cfg.get('model', {}).get('cylinder')
    if spec is None:
        raise ValueError(f'{cfg.filename}: expected an OccCylindrical config '
                         '(model.cylinder), found none.')
    spec = dict(spec)
    shapes = shapes or [tuple(spec['shape'])]
    return [
        CylinderGrid.for_box(cfg.point_cloud_range, **dict(spec, shape=s))
        for s in shapes
    ]


def _metric(cfg: Config) -> OccupancyMetric:
    """The config's metric with its label rules only (convention, classes,
    ignore label, camera mask), without subsets, ranges or files."""
    rules = ('convention', 'class_names', 'ignore_index', 'use_camera_mask')
    evaluator = cfg.test_evaluator
    return OccupancyMetric(
        **{k: evaluator[k]
           for k in rules if k in evaluator})


def measure(cfg: Config,
            shapes: Sequence[Tuple[int, int, int]] = None,
            split: str = 'val',
            data_root: str = None) -> Dict[str, dict]:
    """Score the majority labels of every shape on a split with the
    config's metric (so its convention decides the empty class, the
    ignored voxels and the camera mask).

    Returns:
        dict: Per shape ``'RxTxZ'``: ``IoU``, ``mIoU`` and ``classes``
        (name -> IoU, NaN where the class never occurs), in percent.
    """
    cylinders = _cylinders(cfg, shapes)
    metrics = [_metric(cfg) for _ in cylinders]
    grid = tuple(cfg.grid_size)
    cells = [
        cell_of_voxels(grid, cfg.point_cloud_range, cfg.voxel_size, c)
        for c in cylinders
    ]
    for index, (sample,
                occ) in enumerate(labelled_samples(cfg, split, data_root)):
        data = sample['data_samples']
        for cylinder, cell, metric in zip(cylinders, cells, metrics):
            pred = majority_labels(occ, cell, cylinder.num_voxels,
                                   metric.num_classes, metric.ignore_index,
                                   metric.empty_index)
            metric.process({}, [
                dict(
                    gt_occ=occ,
                    pred_occ=pred,
                    mask_camera=data.get('mask_camera'),
                    sample_idx=f'{split} sample {index}')
            ])
    out = {}
    for cylinder, metric in zip(cylinders, metrics):
        scores = metric.compute_metrics(metric.results)
        out['x'.join(str(s) for s in cylinder.shape)] = dict(
            IoU=scores['IoU'],
            mIoU=scores['mIoU'],
            classes={n: scores[n]
                     for n in metric.class_names})
    return out


def main(argv=None) -> Dict[str, dict]:
    """Measure and print; returns the numbers."""
    args = parse_args(argv)
    cfg = load_tool_config(args)
    out = measure(cfg, args.shapes, args.split, args.data_root)
    print(f'{args.config} ({args.split}): the ground truth kept at the '
          'majority class of each cylinder cell, IoU in %')
    keys = list(out)
    print('  ' + 'cylinder'.ljust(22) + ''.join(k.rjust(14) for k in keys))
    for row in ('IoU', 'mIoU'):
        print('  ' + row.ljust(22) + ''.join(f'{out[k][row]:14.2f}'
                                             for k in keys))
    for name in out[keys[0]]['classes']:
        print('  ' + name.ljust(22) +
              ''.join(f'{out[k]["classes"][name]:14.2f}' for k in keys))
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(
                dict(shapes=out, config=args.config, split=args.split),
                f,
                indent=1)
    return out


if __name__ == '__main__':
    with cfg_errors_exit():
        main()
