#!/usr/bin/env python
"""Which classes do the synthetic world's cameras show? Per class of a split.

    python tools/analysis_tools/camera_visibility.py CONFIG [--split train] \\
        [--data-root DIR] [--cells 12 20] [--json OUT.json]

The generator of the synthetic world writes, next to every camera image, the
raw lidarseg class seen at each pixel (``synthetic_gt/cam_labels``, see
:func:`projects.occ_common.synthetic.camera_label_path`; real
nuScenes has no such maps). For the key frames of a split (the config's
test or training info file) this counts, per occupancy class: the share of
all pixels of the six views, and the cells of a ``--cells`` grid laid over
every image in which the class covers the most pixels (12 x 20 is the
feature map of the small configs: a 192 x 320 input at stride 16). Pixels
of the sky (and lidarseg noise) count as ``sky/noise``. Beside
``tools/analysis_tools/lidar_visibility.py`` it tells whether a class the model
misses
is one its sensors barely show: the learning benchmark used both for
other flat (2026-11-27, 8bd93ad), 0.8 % of the occupied voxels of its
held-out scenes but 0.08 % of their pixels.
"""
import argparse
import json
import os.path as osp
from typing import Dict, Sequence, Tuple

import numpy as np
from mmengine.config import Config

from projects.occ_common.apis.split_dataset import (add_split_arguments,
                                                    build_split_dataset,
                                                    load_tool_config)
from projects.occ_common.datasets.nuscenes_classes import (OCC_CLASS_NAMES,
                                                           lidarseg_to_occ16)
from projects.occ_common.engine.config_checks import (CfgOptionsAction,
                                                      cfg_errors_exit)
from projects.occ_common.synthetic import camera_label_path

#: Name of occupancy label 0 in the pixel maps: the sky (raw class 0 of
#: the maps) and lidarseg noise.
SKY = 'sky/noise'


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('config', help='a config of this library')
    add_split_arguments(parser)
    parser.add_argument('--cells', type=int, nargs=2, default=(12, 20),
                        metavar=('ROWS', 'COLS'),
                        help='grid laid over every image (default: the '
                        'small configs\' 12 x 20 feature map)')
    parser.add_argument('--json', default=None, help='write the numbers')
    parser.add_argument('--cfg-options', nargs='+', action=CfgOptionsAction,
                        help='config overrides, as for tools/test.py')
    return parser.parse_args(argv)


def cell_majority(labels: np.ndarray, cells: Tuple[int, int],
                  num_labels: int) -> np.ndarray:
    """How many cells of a grid over ``labels`` each label wins.

    The image is cut into ``rows x cols`` cells at the rounded multiples
    of ``H / rows`` and ``W / cols`` (so any image size works); a cell
    goes to the label covering most of its pixels, the lowest label on a
    tie.

    Args:
        labels (np.ndarray): Integer labels in ``[0, num_labels)``.
            Shape (H, W).
        cells (tuple[int, int]): ``(rows, cols)``, each at most the
            image's size on that axis.
        num_labels (int): Number of labels.

    Returns:
        np.ndarray: Cells won per label, int64. Shape (num_labels,).
    """
    height, width = labels.shape
    rows, cols = cells
    if not (0 < rows <= height and 0 < cols <= width):
        raise ValueError(f'a {rows} x {cols} grid does not fit a {height} '
                         f'x {width} image')
    row_edges = np.round(np.linspace(0, height, rows + 1)).astype(int)
    col_edges = np.round(np.linspace(0, width, cols + 1)).astype(int)
    # Pixel counts of every (cell, label) pair in one bincount.
    cell = (np.searchsorted(row_edges, np.arange(height), 'right') - 1
            )[:, None] * cols + (
                np.searchsorted(col_edges, np.arange(width), 'right') - 1)
    counts = np.bincount((cell * num_labels + labels).ravel(),
                         minlength=rows * cols * num_labels)
    winners = counts.reshape(rows * cols, num_labels).argmax(axis=1)
    return np.bincount(winners, minlength=num_labels)


class CameraCount:
    """Per-label sums over images: pixels and cells won.

    Args:
        cells (tuple[int, int]): The grid of :func:`cell_majority`.
        num_labels (int): Labels ``0 .. num_labels - 1``. Defaults to 17
            (sky/noise and the 16 occupancy classes).
    """

    def __init__(self, cells: Tuple[int, int], num_labels: int = 17) -> None:
        self.cells = tuple(cells)
        self.num_labels = num_labels
        self.pixels = np.zeros(num_labels, np.int64)
        self.cells_won = np.zeros(num_labels, np.int64)
        self.images = 0

    def update(self, labels: np.ndarray, source: str = '') -> None:
        """Add one image's labels (H, W), each in ``[0, num_labels)``."""
        labels = np.asarray(labels, np.int64)
        if labels.ndim != 2 or labels.size == 0 or labels.min() < 0 or \
                labels.max() >= self.num_labels:
            raise ValueError(
                f'{source or "labels"}: expected a (H, W) map of labels in '
                f'[0, {self.num_labels}), got shape {labels.shape}' +
                (f' with values {labels.min()}..{labels.max()}'
                 if labels.size else ''))
        self.pixels += np.bincount(labels.ravel(), minlength=self.num_labels)
        self.cells_won += cell_majority(labels, self.cells, self.num_labels)
        self.images += 1

    def summary(self, names: Sequence[str]) -> Dict[str, dict]:
        """Per label, named by ``names``: ``pixels`` (% of all pixels) and
        ``cells`` (cells won), every label listed."""
        if len(names) != self.num_labels:
            raise ValueError(f'{len(names)} names for {self.num_labels} '
                             'labels')
        total = max(int(self.pixels.sum()), 1)
        return {
            name: dict(pixels=100.0 * self.pixels[label] / total,
                       cells=int(self.cells_won[label]))
            for label, name in enumerate(names)
        }


def read_label_map(path: str) -> np.ndarray:
    """One image's occupancy labels (0 sky/noise, 1..16) from its raw
    lidarseg class map. Shape (H, W), uint8.

    Raises:
        FileNotFoundError: If the map is missing (not a synthetic world,
            or one written without camera labels).
    """
    from PIL import Image

    if not osp.isfile(path):
        raise FileNotFoundError(
            f'{path}: no per-pixel class map; camera_visibility.py needs a '
            'synthetic world written with its camera labels '
            '(tools/dataset_converters/create_synthetic_nuscenes.py)')
    with Image.open(path) as image:
        raw = np.asarray(image)
    return lidarseg_to_occ16(raw, source=path)


def measure(cfg: Config, split: str = 'val', data_root: str = None,
            cells: Tuple[int, int] = (12, 20)) -> dict:
    """:meth:`CameraCount.summary` over the key frames of ``split``, plus
    ``samples`` and ``images``."""
    dataset = build_split_dataset(cfg, split, data_root)
    count = CameraCount(cells)
    for index in range(len(dataset)):
        images = dataset.get_data_info(index).get('images') or {}
        if not images:
            raise ValueError(f'{dataset.ann_file}, sample {index}: no '
                             'camera images in the info')
        for view in images.values():
            path = osp.join(dataset.data_root,
                            camera_label_path(view['img_path']))
            count.update(read_label_map(path), path)
    return dict(classes=count.summary((SKY, ) + tuple(OCC_CLASS_NAMES)),
                samples=len(dataset), images=count.images)


def main(argv=None) -> dict:
    """Measure and print; returns the numbers."""
    args = parse_args(argv)
    cfg = load_tool_config(args)
    out = measure(cfg, args.split, args.data_root, tuple(args.cells))
    rows, cols = args.cells
    print(f'{args.config} ({args.split}, {out["samples"]} samples, '
          f'{out["images"]} images): % of the pixels per class and the '
          f'cells of a {rows} x {cols} grid it covers most')
    for name, row in out['classes'].items():
        print(f'  {name:22s} {row["pixels"]:7.2f} % {row["cells"]:>9,d}')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(dict(out, config=args.config, split=args.split,
                           cells=[rows, cols]), f, indent=1)
    return out


if __name__ == '__main__':
    with cfg_errors_exit():
        main()
