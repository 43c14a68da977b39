"""Occupancy projected onto the camera images.

The centre of every drawn voxel is projected with the sample's
``lidar2img`` (``img_aug_matrix @ cam2img @ lidar2cam``, so augmented
images line up) and splatted as a small square in its class colour; where
several voxels reach one pixel the nearest wins (a z-buffer), so the
overlay shows what the camera would see of the grid.
"""
from typing import Optional, Sequence

import numpy as np

from .label_grid import occupied_voxels


def voxel_centres(index: np.ndarray, point_cloud_range: Sequence[float],
                  voxel_size: Sequence[float]) -> np.ndarray:
    """Metric centres of voxels given by index.

    Args:
        index (np.ndarray): Voxel indices (x, y, z). Shape (M, 3).
        point_cloud_range (Sequence[float]): ``(x0, y0, z0, x1, y1, z1)``.
        voxel_size (Sequence[float]): ``(x, y, z)`` metres.

    Returns:
        np.ndarray: Shape (M, 3), float64.
    """
    low = np.asarray(point_cloud_range[:3], dtype=np.float64)
    return low + (index + 0.5) * np.asarray(voxel_size, dtype=np.float64)


def overlay_on_cameras(images: np.ndarray,
                       labels: np.ndarray,
                       lidar2img: np.ndarray,
                       point_cloud_range: Sequence[float],
                       voxel_size: Sequence[float],
                       palette: np.ndarray,
                       empty_label: int,
                       ignore_index: int = 255,
                       mask: Optional[np.ndarray] = None,
                       alpha: float = 0.6,
                       radius: int = 1,
                       min_depth: float = 0.1,
                       name: str = 'occupancy') -> np.ndarray:
    """Blend the projected voxels into every view.

    Pixel ``(row, col)`` covers ``[col, col + 1) x [row, row + 1)`` in
    image coordinates, as in the data pipeline's depth maps.

    Args:
        images (np.ndarray): RGB views, Shape (N, H, W, 3), uint8.
        labels (np.ndarray): Shape (X, Y, Z), int.
        lidar2img (np.ndarray): Grid frame to pixels, Shape (N, 4, 4).
        point_cloud_range (Sequence[float]): Grid extent.
        voxel_size (Sequence[float]): Metres per voxel.
        palette (np.ndarray): Shape (C, 3), uint8.
        empty_label (int): Label not drawn.
        ignore_index (int): Label not drawn. Defaults to 255.
        mask (np.ndarray, optional): Voxels to draw, Shape (X, Y, Z).
            Defaults to None (all).
        alpha (float): Opacity of the voxel colour. Defaults to 0.6.
        radius (int): A voxel covers ``(2 * radius + 1)`` pixels square.
            Defaults to 1.
        min_depth (float): Voxels nearer than this (metres along the
            optical axis) are not drawn. Defaults to 0.1.
        name (str): Named in errors. Defaults to 'occupancy'.

    Returns:
        np.ndarray: Shape (N, H, W, 3), uint8.

    Raises:
        ValueError: If ``images`` and ``lidar2img`` disagree in shape.
    """
    images = np.asarray(images)
    lidar2img = np.asarray(lidar2img, dtype=np.float64)
    if images.ndim != 4 or images.shape[-1] != 3:
        raise ValueError('Expected RGB images of shape (N, H, W, 3), got '
                         f'{images.shape}.')
    if lidar2img.shape != (len(images), 4, 4):
        raise ValueError(f'Expected lidar2img of shape ({len(images)}, 4, '
                         f'4) for {len(images)} images, got '
                         f'{lidar2img.shape}.')
    out = images.astype(np.float64)
    drawn = occupied_voxels(labels, len(palette), empty_label, ignore_index,
                            mask, name)
    index = np.argwhere(drawn)
    if len(index) == 0:
        return images.astype(np.uint8)
    centres = voxel_centres(index, point_cloud_range, voxel_size)
    colours = palette[labels[tuple(index.T)]].astype(np.float64)
    height, width = images.shape[1:3]
    offsets = np.arange(-radius, radius + 1)
    d_row, d_col = (g.ravel() for g in np.meshgrid(offsets, offsets))
    for view in range(len(images)):
        cam = centres @ lidar2img[view, :3, :3].T + lidar2img[view, :3, 3]
        depth = cam[:, 2]
        front = depth > min_depth
        col = np.floor(cam[front, 0] / depth[front]).astype(np.int64)
        row = np.floor(cam[front, 1] / depth[front]).astype(np.int64)
        # Every voxel covers a square of pixels around its centre.
        rows = (row[:, None] + d_row).ravel()
        cols = (col[:, None] + d_col).ravel()
        depths = np.repeat(depth[front], len(d_row))
        colour = np.repeat(colours[front], len(d_row), axis=0)
        inside = ((rows >= 0) & (rows < height) & (cols >= 0) &
                  (cols < width))
        pixel = rows[inside] * width + cols[inside]
        near_first = np.argsort(depths[inside], kind='stable')
        # The first occurrence of a pixel in depth order is the nearest.
        pixel, first = np.unique(pixel[near_first], return_index=True)
        flat = out[view].reshape(-1, 3)
        flat[pixel] = (alpha * colour[inside][near_first][first] +
                       (1 - alpha) * flat[pixel])
    return np.rint(out).astype(np.uint8)
