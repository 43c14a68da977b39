"""Occupancy ground truth of a world: voxelisation and visibility masks.

Two label formats are produced for every key frame:

* SurroundOcc: a 200x200x16 grid of 0.5 m voxels in the key frame's LiDAR
  frame over x, y in [-50, 50], z in [-5, 3], stored sparsely as the
  ``(N, 4)`` integer array ``ix, iy, iz, label`` of occupied voxels with
  ``i = floor((coord - min) / 0.5)`` and labels 1..16 (0 = noise).
* Occ3D-nuScenes: a 200x200x16 grid of 0.4 m voxels in the ego frame over
  x, y in [-40, 40], z in [-1, 5.4], stored densely as ``semantics``
  (0 others, 1..16, 17 free) with ``mask_lidar`` (voxels LiDAR rays
  traversed or hit) and ``mask_camera`` (voxels seen from a camera centre
  before the first occupied voxel, which is included).

A voxel is occupied when any of its ``s^3`` sub-sample points lies inside
an object (or the ground slab); objects are written after buildings,
vegetation and the ground, so small things keep their voxels. Ray
traversal is the exact voxel walk of :mod:`..geometry.voxel_walk`
(Amanatides & Woo, 1987), vectorised over rays; the occupancy label
generator walks the same way.
"""
import numpy as np

from ..datasets.nuscenes_classes import LIDARSEG_RAW_TO_OCC16, OCC3D_FREE_LABEL
from ..geometry.voxel_walk import OccGrid, traverse
from .geometry import invert_transform
from .world import GROUND_THICKNESS, World

#: Marker of empty voxels in the raw-class grids of this module.
RAW_FREE = 255
_STUFF_CLASSES = (28, 30, 29)  # manmade, vegetation, static.other


#: SurroundOcc's grid (LiDAR frame).
SURROUNDOCC_GRID = OccGrid((-50.0, -50.0, -5.0), 0.5, (200, 200, 16))
#: Occ3D-nuScenes' grid (ego frame).
OCC3D_GRID = OccGrid((-40.0, -40.0, -1.0), 0.4, (200, 200, 16))


def _check_upright(grid2world: np.ndarray) -> None:
    """The ground slab and the box tests assume the grid's z is world z."""
    if abs(grid2world[2, 2] - 1.0) > 1e-6:
        raise ValueError('Expected a grid frame whose z axis is the world\'s '
                         f'(a yaw-only rotation), got rotation\n'
                         f'{grid2world[:3, :3]}.')


def voxelize(world: World, t: float, grid2world: np.ndarray, grid: OccGrid,
             subsamples: int = 2) -> np.ndarray:
    """Raw lidarseg class of every voxel of a grid.

    Args:
        world (World): The scene.
        t (float): Seconds since the scene's first sweep.
        grid2world (np.ndarray): Grid frame -> global; its rotation must be
            about z only. Shape (4, 4).
        grid (OccGrid): The grid.
        subsamples (int): Sub-sample points per voxel edge. Defaults to 2.

    Returns:
        np.ndarray: Raw class per voxel, :data:`RAW_FREE` where empty,
        uint8. Shape (X, Y, Z).
    """
    _check_upright(grid2world)
    vs, s = grid.voxel_size, subsamples
    offsets = ((np.arange(s) + 0.5) / s - 0.5) * vs
    labels = np.full(grid.shape, RAW_FREE, dtype=np.uint8)
    # Ground: the layers whose sub-samples meet the slab get the majority
    # ground class of the column's sub-samples.
    z_sub = (grid.centers(2)[:, None] + offsets[None]) + grid2world[2, 3]
    layers = ((z_sub >= -GROUND_THICKNESS) & (z_sub <= 0)).any(axis=1)
    if layers.any():
        xs = (grid.centers(0)[:, None] + offsets[None]).ravel()
        ys = (grid.centers(1)[:, None] + offsets[None]).ravel()
        gx, gy = np.meshgrid(xs, ys, indexing='ij')
        rot, trans = grid2world[:2, :2], grid2world[:2, 3]
        xy = np.stack([rot[0, 0] * gx + rot[0, 1] * gy + trans[0],
                       rot[1, 0] * gx + rot[1, 1] * gy + trans[1]], axis=-1)
        sub_class = world.ground_class(xy).reshape(grid.shape[0], s,
                                                   grid.shape[1], s)
        candidates = np.unique(sub_class)
        votes = np.stack([(sub_class == c).sum(axis=(1, 3))
                          for c in candidates])
        column = candidates[np.argmax(votes, axis=0)]
        labels[:, :, layers] = column[:, :, None]
    boxes = world.boxes
    world2grid = invert_transform(grid2world)
    corners = boxes.corners_at(t) @ world2grid[:3, :3].T + world2grid[:3, 3]
    centers = boxes.centers_at(t)
    order = sorted(range(len(boxes)),
                   key=lambda i: boxes.raw_class[i] not in _STUFF_CLASSES)
    shape = np.asarray(grid.shape)
    for box in order:
        lo = np.floor((corners[box].min(0) - grid.lower) / vs).astype(int)
        hi = np.ceil((corners[box].max(0) - grid.lower) / vs).astype(int)
        lo, hi = np.maximum(lo, 0), np.minimum(hi, shape)
        if (lo >= hi).any():
            continue
        axes = [(grid.centers(a)[lo[a]:hi[a], None] + offsets[None]).ravel()
                for a in range(3)]
        # Grid -> box frame is a 2D rotation plus a translation, so the
        # inside test separates into an xy part and a z part.
        yaw = boxes.yaw[box]
        c, s_ = np.cos(yaw), np.sin(yaw)
        world2box = np.array([[c, s_], [-s_, c]])
        to_box = world2box @ grid2world[:2, :2]
        shift = world2box @ (grid2world[:2, 3] - centers[box, :2])
        gx, gy = np.meshgrid(axes[0], axes[1], indexing='ij')
        half = boxes.size[box] / 2
        inside_xy = ((np.abs(to_box[0, 0] * gx + to_box[0, 1] * gy +
                             shift[0]) <= half[0])
                     & (np.abs(to_box[1, 0] * gx + to_box[1, 1] * gy +
                               shift[1]) <= half[1]))
        z_world = axes[2] + grid2world[2, 3]
        inside_z = np.abs(z_world - centers[box, 2]) <= half[2]
        inside = inside_xy[:, :, None] & inside_z[None, None]
        n = hi - lo
        inside = inside.reshape(n[0], s, n[1], s, n[2], s).any(axis=(1, 3,
                                                                     5))
        window = labels[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        window[inside] = boxes.raw_class[box]
    return labels


def to_surroundocc(raw_grid: np.ndarray) -> np.ndarray:
    """Sparse SurroundOcc labels of a raw-class grid.

    Args:
        raw_grid (np.ndarray): Raw class per voxel, :data:`RAW_FREE` where
            empty. Shape (X, Y, Z).

    Returns:
        np.ndarray: ``ix, iy, iz, label`` of occupied voxels (label 0..16,
        0 = noise), sorted by index. int32: half the size of int64 on disk,
        and flat indices ``(ix * 200 + iy) * 16 + iz`` still fit. Shape
        (N, 4).
    """
    index = np.argwhere(raw_grid != RAW_FREE)
    label = LIDARSEG_RAW_TO_OCC16[raw_grid[tuple(index.T)]]
    return np.concatenate([index, label[:, None]], axis=1).astype(np.int32)


def to_occ3d_semantics(raw_grid: np.ndarray) -> np.ndarray:
    """Occ3D ``semantics`` of a raw-class grid (17 = free).

    Args:
        raw_grid (np.ndarray): Raw class per voxel. Shape (X, Y, Z).

    Returns:
        np.ndarray: Labels 0..17, uint8. Shape (X, Y, Z).
    """
    free = raw_grid == RAW_FREE
    semantics = LIDARSEG_RAW_TO_OCC16[np.where(free, 0, raw_grid)]
    return np.where(free, OCC3D_FREE_LABEL, semantics).astype(np.uint8)


def lidar_mask(grid: OccGrid, world2grid: np.ndarray, sweeps: list
               ) -> np.ndarray:
    """Occ3D ``mask_lidar``: voxels traversed or hit by the rays of
    sweeps.

    Args:
        grid (OccGrid): The grid.
        world2grid (np.ndarray): Global -> grid frame. Shape (4, 4).
        sweeps (list): :class:`.lidar.Sweep` objects to aggregate.

    Returns:
        np.ndarray: Mask. Shape (X, Y, Z), bool.
    """
    mask = np.zeros(grid.shape, dtype=bool)
    rotation, translation = world2grid[:3, :3], world2grid[:3, 3]
    for sweep in sweeps:
        mask |= traverse(grid, rotation @ sweep.origin + translation,
                         sweep.ray_dirs @ rotation.T, sweep.ray_length)
    return mask


def camera_mask(grid: OccGrid, occupied: np.ndarray, cameras: list,
                cam2grid: list) -> np.ndarray:
    """Occ3D ``mask_camera``: voxels seen from any camera centre, up to and
    including the first occupied voxel along each pixel ray.

    Args:
        grid (OccGrid): The grid.
        occupied (np.ndarray): Occupied voxels. Shape (X, Y, Z), bool.
        cameras (list): :class:`.camera.Camera` objects whose pixel rays
            are cast (their resolution sets the ray density).
        cam2grid (list): Camera -> grid transform of each camera.
            Shape (4, 4) each.

    Returns:
        np.ndarray: Mask. Shape (X, Y, Z), bool.
    """
    mask = np.zeros(grid.shape, dtype=bool)
    reach = float(np.linalg.norm(grid.upper - np.asarray(grid.lower)))
    for camera, transform in zip(cameras, cam2grid):
        rays = camera.pixel_rays()
        dirs = rays @ transform[:3, :3].T
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        mask |= traverse(grid, transform[:3, 3], dirs,
                         np.full(len(dirs), reach), occupied)
    return mask
