#!/usr/bin/env python
"""Pictures of every sensor corruption on one sample.

    python tools/misc/visualize_corruptions.py --info INFO.pkl \\
        --data-root ROOT --out DIR [--sample 0] [--severities 1 3 5] \\
        [--conditions ...]

Loads the sample with the SurroundOcc base config's test loaders (an info
file of ``tools/create_data.py``, e.g. one made from the real nuScenes
sample with ``--from-mmdet3d-info``) and draws, for severity 0 (clean)
and each of ``--severities``:

* ``camera_pixels.jpg``: CAM_FRONT under each pixel corruption;
* ``camera_views.jpg``: the six views (missing ones grey) under crash,
  blackout, lost frames and missing views;
* ``lidar.jpg``: the cloud from above (50 m around the sensor) under each
  LiDAR condition;
* ``cross_sensor.jpg``: the points projected into CAM_FRONT with the
  calibration the model is told (spatial misalignment) and the late cloud
  with the true one (temporal misalignment).
"""
import argparse
import copy
import os
import os.path as osp
from typing import List

import numpy as np

#: The six views as a 2 x 3 mosaic: front row, then back row.
MOSAIC = (('CAM_FRONT_LEFT', 'CAM_FRONT', 'CAM_FRONT_RIGHT'),
          ('CAM_BACK_LEFT', 'CAM_BACK', 'CAM_BACK_RIGHT'))
REPO = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
#: Width in pixels of one drawn view.
TILE_WIDTH = 320


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--info', required=True, help='info file')
    parser.add_argument('--data-root', required=True,
                        help='root of its paths')
    parser.add_argument('--out', required=True, help='output folder')
    parser.add_argument('--sample', type=int, default=0)
    parser.add_argument('--severities', nargs='+', type=int,
                        default=[1, 3, 5])
    parser.add_argument('--conditions', nargs='+', default=None,
                        help='default: all')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--tile-width', type=int, default=TILE_WIDTH,
                        help='width of one drawn view in pixels')
    parser.add_argument(
        '--config', default=osp.join(REPO, 'configs', '_base_', 'datasets',
                                     'surroundocc-nus.py'),
        help='config whose test loaders read the sample (default: the '
        'SurroundOcc base)')
    return parser.parse_args(argv)


def _small(img: np.ndarray, width: int = TILE_WIDTH) -> np.ndarray:
    """A view (BGR uint8) scaled to ``width``, as RGB."""
    import cv2
    height = round(img.shape[0] * width / img.shape[1])
    return cv2.resize(img, (width, height),
                      interpolation=cv2.INTER_AREA)[..., ::-1]


def _front(results: dict) -> np.ndarray:
    return results['img'][list(results['cam_names']).index('CAM_FRONT')]


def mosaic(results: dict, width: int = TILE_WIDTH // 2) -> np.ndarray:
    """The six views as 2 x 3 tiles (RGB); a missing view is grey."""
    names = list(results['cam_names'])
    tiles = []
    height = None
    for row in MOSAIC:
        cells = []
        for cam in row:
            if cam in names:
                cells.append(_small(results['img'][names.index(cam)], width))
                height = cells[-1].shape[0]
            else:
                cells.append(None)
        tiles.append(cells)
    grey = np.full((height or width // 2, width, 3), 128, np.uint8)
    return np.concatenate([
        np.concatenate([c if c is not None else grey for c in row], axis=1)
        for row in tiles
    ], axis=0)


def projected(results: dict, points: np.ndarray,
              width: int = TILE_WIDTH) -> np.ndarray:
    """``points`` drawn into CAM_FRONT with ``results``' lidar2img,
    coloured by depth (RGB)."""
    import cv2
    from matplotlib import colormaps
    index = list(results['cam_names']).index('CAM_FRONT')
    img = _front(results).copy()
    lidar2img = np.asarray(results['lidar2img'])[index]
    xyz1 = np.column_stack([points[:, :3], np.ones(len(points))])
    uvz = xyz1 @ lidar2img.T
    front = uvz[:, 2] > 1.0
    uv = uvz[front, :2] / uvz[front, 2:3]
    depth = uvz[front, 2]
    inside = ((uv[:, 0] >= 0) & (uv[:, 0] < img.shape[1]) &
              (uv[:, 1] >= 0) & (uv[:, 1] < img.shape[0]))
    colours = colormaps['turbo'](np.clip(depth[inside] / 50.0, 0, 1))
    radius = max(1, round(img.shape[1] / 500))
    for (u, v), colour in zip(uv[inside].astype(int), colours):
        bgr = tuple(int(255 * c) for c in colour[2::-1])
        cv2.circle(img, (u, v), radius, bgr, -1)
    return _small(img, width)


def key_frame(results: dict) -> np.ndarray:
    """The key frame's points (time lag 0) of the merged cloud."""
    from projects.occ_common.transforms.corruptions.lidar import points_array
    points = points_array(results)
    column = results.get('points_time_dim')
    return points if column is None else points[points[:, column] == 0]


def _grid(rows: List[List[np.ndarray]], names: List[str],
          severities: List[int], path: str) -> None:
    """Images as a labelled grid (rows: conditions, columns: severity)."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt
    height, width = rows[0][0].shape[:2]
    scale = 1 / 100
    fig, axes = plt.subplots(
        len(rows), len(rows[0]),
        figsize=(len(rows[0]) * width * scale,
                 len(rows) * (height * scale + 0.25)), squeeze=False)
    for r, (row, name) in enumerate(zip(rows, names)):
        for c, img in enumerate(row):
            axes[r, c].imshow(img)
            axes[r, c].set_xticks([])
            axes[r, c].set_yticks([])
            axes[r, c].set_title(
                f'{name} s{severities[c]}' if severities[c] else
                f'{name}: clean', fontsize=7)
    fig.tight_layout(pad=0.3)
    fig.savefig(path, dpi=100, bbox_inches='tight', pad_inches=0.05,
                pil_kwargs=dict(quality=80))
    plt.close(fig)


def _bev(points_list: List[np.ndarray], names: List[str],
         severities: List[int], path: str) -> None:
    """Clouds from above, 50 m around the sensor, coloured by height."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt
    rows = len(points_list) // len(severities)
    fig, axes = plt.subplots(rows, len(severities),
                             figsize=(2.6 * len(severities), 2.6 * rows),
                             squeeze=False)
    for k, points in enumerate(points_list):
        ax = axes[k // len(severities), k % len(severities)]
        ax.scatter(points[:, 0], points[:, 1], s=0.05, c=points[:, 2],
                   cmap='viridis', vmin=-3, vmax=3, rasterized=True)
        ax.set_xlim(-50, 50)
        ax.set_ylim(-50, 50)
        ax.set_aspect('equal')
        ax.set_xticks([])
        ax.set_yticks([])
        severity = severities[k % len(severities)]
        ax.set_title(f'{names[k // len(severities)]} ' +
                     (f's{severity}: {len(points)} points' if severity else
                      f'clean: {len(points)} points'), fontsize=7)
    fig.tight_layout(pad=0.3)
    fig.savefig(path, dpi=80, pil_kwargs=dict(quality=80))
    plt.close(fig)


def main(argv=None) -> List[str]:
    """Draw the pictures; returns the files written."""
    from mmengine.config import Config

    from projects.occ_common.apis import loaded_inputs
    from projects.occ_common.transforms.corruptions import (CONDITIONS,
                                                            OccCorruption)
    from projects.occ_common.transforms.corruptions.lidar import points_array

    args = parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    sample = loaded_inputs(Config.fromfile(args.config), args.data_root,
                           args.info, args.sample)
    conditions = args.conditions or list(CONDITIONS)
    severities = [0] + list(args.severities)

    def corrupted(condition, severity):
        if severity == 0:
            return sample
        return OccCorruption(condition, severity,
                             args.seed)(copy.deepcopy(sample))

    views = ('camera_crash', 'camera_blackout', 'frame_lost',
             'missing_views')
    groups = dict(
        camera_pixels=[c for c in conditions
                       if CONDITIONS[c].family == 'camera' and
                       c not in views],
        camera_views=[c for c in conditions if c in views],
        lidar=[c for c in conditions if CONDITIONS[c].family == 'lidar'],
        cross_sensor=[c for c in conditions
                      if CONDITIONS[c].family == 'cross-sensor'])
    written = []
    for group, names in groups.items():
        if not names:
            continue
        runs = [[corrupted(c, s) for s in severities] for c in names]
        if group == 'lidar':
            path = osp.join(args.out, 'lidar.jpg')
            _bev([points_array(r) for row in runs for r in row], names,
                 severities, path)
        else:
            width = args.tile_width
            draw = dict(camera_pixels=lambda r: _small(_front(r), width),
                        camera_views=lambda r: mosaic(r, width // 2),
                        cross_sensor=lambda r: projected(
                            r, key_frame(r), width))[group]
            path = osp.join(args.out, f'{group}.jpg')
            _grid([[draw(r) for r in row] for row in runs], names,
                  severities, path)
        written.append(path)
        print(f'wrote {path}')
    return written


if __name__ == '__main__':
    main()
