"""Occ3D's visibility masks by ray casting (the library's voxel walk).

* ``mask_lidar``: the voxels the rays of the key frame's last sweeps
  walked through or ended in (a return's voxel included).
* ``mask_camera``: the voxels seen from the key frame's cameras: pixel
  rays walked from each camera centre up to and including the first
  occupied voxel of the generated labels.

Both use :func:`..geometry.voxel_walk.traverse`, as the synthetic world's
exact masks do.
"""
from typing import List

import numpy as np

from ...geometry.voxel_walk import OccGrid, traverse
from .accumulation import SweepRays
from .sequence import CameraView

#: Distance at which ``camera_ray_spacing`` is met: the Occ3D grid's half
#: width, metres.
CAMERA_SPACING_RANGE = 40.0


def lidar_mask(grid: OccGrid, global2grid: np.ndarray,
               rays: List[SweepRays], no_return_range: float) -> np.ndarray:
    """Voxels traversed or hit by the rays of some sweeps.

    Args:
        grid (OccGrid): The grid.
        global2grid (np.ndarray): Global -> grid frame. Shape (4, 4).
        rays (List[SweepRays]): The sweeps.
        no_return_range (float): Length of the rays without a return,
            metres (0: they are left out).

    Returns:
        np.ndarray: bool. Shape (X, Y, Z).
    """
    mask = np.zeros(grid.shape, dtype=bool)
    rot, shift = global2grid[:3, :3], global2grid[:3, 3]
    for sweep in rays:
        origin = rot @ sweep.origin + shift
        delta = sweep.ends @ rot.T + shift - origin
        length = np.linalg.norm(delta, axis=1)
        ok = length > 1e-6
        mask |= traverse(grid, origin, delta[ok] / length[ok, None],
                         length[ok])
        if no_return_range > 0 and len(sweep.missing):
            mask |= traverse(grid, origin, sweep.missing @ rot.T,
                             np.full(len(sweep.missing), no_return_range))
    return mask


def pixel_stride(camera: CameraView, spacing: float) -> int:
    """Pixels between camera-mask rays: neighbouring rays at most
    ``spacing`` metres apart at :data:`CAMERA_SPACING_RANGE`."""
    focal = float(max(camera.intrinsic[0, 0], camera.intrinsic[1, 1]))
    return max(1, int(np.floor(spacing / CAMERA_SPACING_RANGE * focal)))


def camera_rays(camera: CameraView, stride: int) -> np.ndarray:
    """Camera-frame directions (z = 1) through the centres of
    ``stride`` x ``stride`` pixel blocks. Shape (R, 3)."""
    u = np.arange(stride / 2, camera.width, stride)
    v = np.arange(stride / 2, camera.height, stride)
    uu, vv = np.meshgrid(u, v)
    k = camera.intrinsic
    x = (uu - k[0, 2]) / k[0, 0]
    y = (vv - k[1, 2]) / k[1, 1]
    return np.stack([x, y, np.ones_like(x)], axis=-1).reshape(-1, 3)


def camera_mask(grid: OccGrid, occupied: np.ndarray,
                cameras: List[CameraView], global2grid: np.ndarray,
                spacing: float) -> np.ndarray:
    """Voxels seen from the cameras up to the first occupied one.

    Args:
        grid (OccGrid): The grid.
        occupied (np.ndarray): bool. Shape (X, Y, Z).
        cameras (List[CameraView]): The key frame's cameras.
        global2grid (np.ndarray): Global -> grid frame. Shape (4, 4).
        spacing (float): See :func:`pixel_stride`.

    Returns:
        np.ndarray: bool. Shape (X, Y, Z).
    """
    mask = np.zeros(grid.shape, dtype=bool)
    reach = float(np.linalg.norm(grid.upper - np.asarray(grid.lower)))
    for camera in cameras:
        cam2grid = global2grid @ camera.cam2global
        dirs = camera_rays(camera, pixel_stride(camera, spacing)) @ (
            cam2grid[:3, :3].T)
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        mask |= traverse(grid, cam2grid[:3, 3], dirs,
                         np.full(len(dirs), reach), occupied)
    return mask
