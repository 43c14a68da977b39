"""The doctor's pictures of a sample: what the checks' numbers are about.

* :func:`camera_picture`: every camera image with the ground truth
  projected onto it (:func:`~...visualization.overlay_on_cameras`) and the
  key frame's LiDAR points as dots coloured by depth: labels or points
  off the image's objects show a calibration or frame bug at a glance;
* :func:`bev_picture`: the ground truth from above
  (:func:`~...visualization.render_bev`), ahead of the car up, with the
  key frame's points in black: a flipped or shifted grid shows as points
  beside the labelled objects.
"""
from typing import Optional

import cv2
import numpy as np

from ...visualization import (class_palette, overlay_on_cameras, render_bev,
                              sample_forward)
from ...visualization.bev_view import columns_to_image
from ...visualization.palette import BACKGROUND
from .grid import LabelGrid
from .labels_lidar import grid_points
from .sample_data import SampleData

#: Height of each camera tile, pixels, and tiles per row.
TILE_HEIGHT, TILES_PER_ROW = 225, 3
#: Pixels per voxel side of the top-down picture.
BEV_SCALE = 2


def _depth_colours(depth: np.ndarray) -> np.ndarray:
    """Near red to far blue over 0-50 m. Shape (P, 3), uint8."""
    ratio = np.clip(depth / 50.0, 0, 1)[:, None]
    return ((1 - ratio) * np.array([230, 30, 30]) +
            ratio * np.array([30, 60, 230])).astype(np.uint8)


def camera_picture(sample: SampleData,
                   grid: Optional[LabelGrid]) -> Optional[np.ndarray]:
    """The cameras with the labels and the LiDAR points drawn on them.

    Args:
        sample (SampleData): With images (cameras without one are left
            out).
        grid (LabelGrid, optional): The config's grid (labels drawn where
            the sample has them).

    Returns:
        np.ndarray | None: RGB, uint8, Shape (H, W, 3); None without
        images.
    """
    tiles = []
    for camera in sample.cameras:
        if camera.image is None:
            continue
        height, width = camera.image.shape[:2]
        scale = TILE_HEIGHT / height
        image = cv2.resize(camera.image, (round(width * scale), TILE_HEIGHT),
                           interpolation=cv2.INTER_AREA)
        to_tile = np.diag([scale, scale, 1.0, 1.0]) @ camera.lidar2img
        if grid is not None and sample.labels is not None:
            grid2lidar = np.linalg.inv(grid.lidar2grid(sample.lidar2ego))
            image = overlay_on_cameras(
                image[None], sample.labels, (to_tile @ grid2lidar)[None],
                grid.pc_range, grid.voxel_size,
                class_palette(grid.class_names), grid.empty_label,
                grid.ignore_index, alpha=0.45)[0]
        cam = sample.points[:, :3] @ to_tile[:3, :3].T + to_tile[:3, 3]
        front = cam[:, 2] > 0.5
        u = np.floor(cam[front, 0] / cam[front, 2]).astype(np.int64)
        v = np.floor(cam[front, 1] / cam[front, 2]).astype(np.int64)
        inside = ((u >= 0) & (u < image.shape[1]) & (v >= 0)
                  & (v < TILE_HEIGHT))
        image = image.copy()
        image[v[inside], u[inside]] = _depth_colours(cam[front, 2][inside])
        cv2.putText(image, camera.name, (6, 18), cv2.FONT_HERSHEY_SIMPLEX,
                    0.5, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(image)
    if not tiles:
        return None
    width = max(tile.shape[1] for tile in tiles)
    rows = []
    for start in range(0, len(tiles), TILES_PER_ROW):
        row = [np.pad(t, ((0, 0), (0, width - t.shape[1]), (0, 0)))
               for t in tiles[start:start + TILES_PER_ROW]]
        row += [np.zeros_like(row[0])] * (TILES_PER_ROW - len(row))
        rows.append(np.concatenate(row, axis=1))
    return np.concatenate(rows, axis=0)


def bev_picture(sample: SampleData, grid: LabelGrid) -> np.ndarray:
    """The labels from above with the key frame's points.

    Args:
        sample (SampleData): The sample (an empty grid without labels).
        grid (LabelGrid): The config's grid.

    Returns:
        np.ndarray: RGB, uint8, Shape (X * 2, Y * 2, 3) or (Y * 2, X * 2,
        3), ahead of the car up.
    """
    labels = sample.labels if sample.labels is not None else np.full(
        grid.shape, grid.empty_label, np.uint8)
    grid2ego = sample.lidar2ego @ np.linalg.inv(
        grid.lidar2grid(sample.lidar2ego))
    forward = sample_forward(grid2ego)
    image = render_bev(labels, class_palette(grid.class_names),
                       grid.empty_label, grid.ignore_index,
                       scale=BEV_SCALE, forward=forward,
                       background=BACKGROUND).copy()
    xyz, _ = grid_points(sample, grid)
    index = np.floor((xyz[:, :2] - grid.pc_range[:2]) /
                     grid.voxel_size[:2]).astype(np.int64)
    inside = np.all((index >= 0) & (index < np.asarray(grid.shape[:2])),
                    axis=1)
    hit = np.zeros(grid.shape[:2], bool)
    hit[tuple(index[inside].T)] = True
    dots = columns_to_image(hit, BEV_SCALE, forward)
    image[dots] = 0
    return image
