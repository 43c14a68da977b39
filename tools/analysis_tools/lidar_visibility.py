#!/usr/bin/env python
"""Which ground-truth voxels does the LiDAR see? Per class of a split.

    python tools/analysis_tools/lidar_visibility.py CONFIG [--split train] \\
        [--data-root DIR] [--json OUT.json]

Runs the samples of a split through the config's test pipeline and counts,
per class: its ground-truth voxels, the share of them that holds at least
one of the points the model gets (key frame and sweeps, ego returns
removed), the share within ``--near`` metres of the working frame's origin
(horizontally) and their mean horizontal range. Every pipeline of this
library keeps points and grid in one working frame (LiDAR for SurroundOcc,
ego for Occ3D), so a point's voxel is ``floor((p - range_min) /
voxel_size)``. A class whose voxels rarely hold a return is one the model
must infer from the cameras and from shape: the learning benchmark used
it to tell why the small OccCylindrical misses bicycles (2026-11-26,
a62c1e8).
"""
import argparse
import json
from typing import Dict, Sequence

import numpy as np
from mmengine.config import Config

from projects.occ_common.apis.split_dataset import (add_split_arguments,
                                                    labelled_samples,
                                                    load_tool_config)
from projects.occ_common.engine.config_checks import (CfgOptionsAction,
                                                      cfg_errors_exit)
from projects.occ_common.transforms.point_labels import point_voxel_index
from projects.occ_common.visualization.camera_overlay import voxel_centres


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('config', help='a config of this library')
    add_split_arguments(parser)
    parser.add_argument('--near', type=float, default=20.0,
                        help='metres: the "near" share\'s horizontal range')
    parser.add_argument('--json', default=None, help='write the numbers')
    parser.add_argument('--cfg-options', nargs='+', action=CfgOptionsAction,
                        help='config overrides, as for tools/test.py')
    return parser.parse_args(argv)


def voxel_hits(occ: np.ndarray, points: np.ndarray,
               pc_range: Sequence[float],
               voxel_size: Sequence[float]) -> np.ndarray:
    """Which voxels hold at least one point.

    Args:
        occ (np.ndarray): The label grid. Shape (X, Y, Z).
        points (np.ndarray): Coordinates first. Shape (P, >= 3).
        pc_range (Sequence[float]): ``(x0, y0, z0, x1, y1, z1)``.
        voxel_size (Sequence[float]): (dx, dy, dz).

    Returns:
        np.ndarray: bool. Shape (X, Y, Z).
    """
    index, inside = point_voxel_index(
        np.asarray(points)[:, :3], occ.shape, pc_range, voxel_size)
    hit = np.zeros(occ.shape, bool)
    hit[tuple(index[inside].T)] = True
    return hit


class VisibilityCount:
    """Per-label sums over samples: voxels, voxels with a return, voxels
    within ``near`` metres and their summed horizontal range.

    Args:
        pc_range (Sequence[float]): ``(x0, y0, z0, x1, y1, z1)``.
        voxel_size (Sequence[float]): (dx, dy, dz).
        near (float): Horizontal range of the "near" share, metres.
    """

    def __init__(self, pc_range: Sequence[float],
                 voxel_size: Sequence[float], near: float) -> None:
        self.pc_range = pc_range
        self.voxel_size = voxel_size
        self.near = near
        # Rows: voxels, with a return, near, summed range; column = label.
        self.sums = np.zeros((4, 0))

    def _radius(self, shape) -> np.ndarray:
        """Horizontal range of every voxel centre. Shape (X, Y, Z)."""
        xy = np.stack(np.meshgrid(np.arange(shape[0]), np.arange(shape[1]),
                                  [0], indexing='ij'), axis=-1)
        centre = voxel_centres(xy, self.pc_range, self.voxel_size)
        radius = np.hypot(centre[..., 0], centre[..., 1])
        return np.broadcast_to(radius, shape)

    def update(self, occ: np.ndarray, points: np.ndarray) -> None:
        """Add one sample: its label grid (X, Y, Z) and points (P, >= 3)."""
        labels = np.asarray(occ, np.int64).ravel()
        radius = self._radius(occ.shape).ravel()
        weights = (None, voxel_hits(occ, points, self.pc_range,
                                    self.voxel_size).ravel(),
                   radius < self.near, radius)
        size = max(labels.max() + 1, self.sums.shape[1])
        sample = np.stack([
            np.bincount(labels, weights=w, minlength=size) for w in weights
        ])
        self.sums = np.pad(self.sums,
                           ((0, 0), (0, size - self.sums.shape[1]))) + sample

    def summary(self, names: Sequence[str]) -> Dict[str, dict]:
        """Per label that has voxels (named by ``names`` where it indexes
        them, else by its number): ``voxels``, ``with_return`` and
        ``near`` (%), ``mean_range_m``."""
        out = {}
        for label in np.flatnonzero(self.sums[0]):
            voxels, hits, near, radius = self.sums[:, label]
            name = names[label] if label < len(names) else str(label)
            out[name] = dict(voxels=int(voxels),
                             with_return=100 * hits / voxels,
                             near=100 * near / voxels,
                             mean_range_m=radius / voxels)
        return out


def measure(cfg: Config, split: str = 'val', data_root: str = None,
            near: float = 20.0) -> Dict[str, dict]:
    """:meth:`VisibilityCount.summary` over the samples of ``split``."""
    count = VisibilityCount(cfg.point_cloud_range, cfg.voxel_size, near)
    for sample, occ in labelled_samples(cfg, split, data_root):
        count.update(occ, sample['inputs']['points'].numpy())
    return count.summary(list(cfg.class_names))


def main(argv=None) -> Dict[str, dict]:
    """Measure and print; returns the numbers."""
    args = parse_args(argv)
    cfg = load_tool_config(args)
    out = measure(cfg, args.split, args.data_root, args.near)
    print(f'{args.config} ({args.split}): ground-truth voxels per class, '
          f'the % that hold a LiDAR return, the % within {args.near:g} m, '
          'the mean range')
    for name, row in out.items():
        print(f'  {name:22s} {row["voxels"]:>11,d} '
              f'{row["with_return"]:6.1f} % {row["near"]:6.1f} % '
              f'{row["mean_range_m"]:6.1f} m')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(dict(classes=out, config=args.config,
                           split=args.split, near_m=args.near), f, indent=1)
    return out


if __name__ == '__main__':
    with cfg_errors_exit():
        main()
