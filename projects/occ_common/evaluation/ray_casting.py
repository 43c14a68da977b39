"""Ray casting of RayIoU: SparseOcc's virtual LiDAR rays and their
Amanatides-Woo traversal of label grids.

The rays (:func:`lidar_ray_directions`) are 39 pitch angles x 360
azimuths (1 degree) from every origin. :func:`cast_rays` traverses the
0.4 m Occ3D grid voxel by voxel (Amanatides & Woo, Eurographics 1987); a
voxel is occupied when its label is not free, and a ray's depth is the
distance from its origin to where it *leaves* the first occupied voxel (as
SparseOcc's kernel records it); a ray that meets none hits nothing.

The traversal is vectorised over all rays of a sample with numpy and
reproduces the arithmetic of SparseOcc's CUDA kernel (``lib/dvr/dvr.cu``:
float32 voxel coordinates of origin and end point, float64 stepping by
repeated addition, its order at ties, float32 depths), so that both give
the same hits ray for ray. Several grids (prediction and ground truth)
are traversed together, since a ray's path is the same in each.

Two departures, neither of which changes RayIoU where SparseOcc's own
result is meaningful: a ray that hits nothing gets depth ``inf`` (the
kernel reports where it leaves the grid, which RayIoU never reads, as
such a ray is free); and a ray from an origin outside the grid (a LiDAR
more than 3.5 m above or 2.8 m below the sample's ego, on a steep road)
that never enters it hits nothing, where the kernel leaves it the label
of voxel (0, 0, 0) at depth -0.4 m, scoring the grid's corner.
"""
import math
from typing import List, NamedTuple, Optional, Sequence

import numpy as np

from ..datasets.nuscenes_classes import OCC3D_CLASS_NAMES

#: Grid the rays traverse: x, y in [-40, 40] m, z in [-1, 5.4] m (Occ3D).
RAY_PC_RANGE = (-40.0, -40.0, -1.0, 40.0, 40.0, 5.4)
#: Edge of the (cubic) voxels, metres.
RAY_VOXEL_SIZE = 0.4
#: Azimuth steps of one degree per beam.
NUM_AZIMUTHS = 360

# SparseOcc's kernel follows a ray for at most this many voxel steps; it
# only matters for origins outside the grid (a ray from inside leaves the
# grid within X + Y + Z steps).
_MAX_STEPS = 1000
# Bit of the traversal code grid that marks the one-voxel border.
_OUTSIDE = np.uint8(128)
# Grids a single traversal can serve (one code bit each).
_MAX_GRIDS = 7
# Compact the arrays of the rays still marching once this share of them is
# finished (finished rays sit on a parking cell until then).
_COMPACT_SHARE = 0.5


class RayHits(NamedTuple):
    """What every ray of a cast meets first.

    Args:
        label (np.ndarray): Label of the first occupied voxel, the free
            label where the ray hits nothing. Shape (N,).
        depth (np.ndarray): float32 distance in metres from the origin to
            where the ray leaves that voxel; ``inf`` where it hits
            nothing. Shape (N,).
    """
    label: np.ndarray
    depth: np.ndarray


def lidar_ray_pitches() -> List[float]:
    """The 39 beam elevations of SparseOcc's virtual LiDAR, radians.

    Ten beams whose slopes are -1, -1/2, ..., -1/10 (pitch atan(k) - pi / 2
    for k = 1..10), then beams continued upwards at the last spacing until
    one reaches 0.21 rad, the top of the nuScenes LiDAR's field of view.
    Each new pitch adds the difference of the previous two, so the list is
    the same float for float as SparseOcc's.

    Returns:
        list[float]: Pitches, ascending, from -pi / 4 to about 0.21.
    """
    pitches = [math.atan(k) - math.pi / 2 for k in range(1, 11)]
    while pitches[-1] < 0.21:
        pitches.append(pitches[-1] + (pitches[-1] - pitches[-2]))
    return pitches


def lidar_ray_directions() -> np.ndarray:
    """Unit directions of the rays cast from every origin.

    Returns:
        np.ndarray: float32, pitch-major (all azimuths 0, 1, ..., 359
        degrees of the lowest beam first). Shape (39 * 360, 3).
    """
    pitch = np.asarray(lidar_ray_pitches())[:, None]
    azimuth = np.deg2rad(np.arange(NUM_AZIMUTHS))[None, :]
    xyz = np.stack(
        np.broadcast_arrays(
            np.cos(pitch) * np.cos(azimuth),
            np.cos(pitch) * np.sin(azimuth), np.sin(pitch)), -1)
    return xyz.reshape(-1, 3).astype(np.float32)


def _voxel_frame(origins: np.ndarray, directions: np.ndarray,
                 pc_range: Sequence[float], voxel_size: float):
    """Ray starts and unit directions in voxel units.

    As in SparseOcc, origin and end point (origin + direction) are taken to
    voxel coordinates in float64 with the float32 voxel size and rounded
    to float32; the direction is their normalised difference in float64.

    Returns:
        tuple[np.ndarray, np.ndarray]: Starts and directions, float64,
        origin-major (ray ``t * R + r``). Shape (3, T * R) each.
    """
    low = np.asarray(pc_range[:3], dtype=np.float32).astype(np.float64)
    scale = np.float64(np.float32(voxel_size))
    start = ((origins - low) / scale).astype(np.float32).astype(np.float64)
    # (3, T, R): direction r added to origin t, then shifted and scaled.
    end = (directions.T.astype(np.float64)[:, None] + origins.T[:, :, None]
           - low[:, None, None]) / scale
    end = end.astype(np.float32).astype(np.float64).reshape(3, -1)
    start = np.repeat(start.T, len(directions), axis=1)
    ray = end - start
    rx, ry, rz = ray
    length = np.sqrt(rx * rx + ry * ry + rz * rz)
    with np.errstate(invalid='ignore', divide='ignore'):
        return start, ray / length


def _first_crossings(start: np.ndarray, unit: np.ndarray):
    """Amanatides-Woo set-up: start voxel, step signs, distance to the
    first boundary and between boundaries per axis (``DBL_MAX`` along an
    axis the ray does not move on), as SparseOcc's kernel computes them.

    Returns:
        tuple[np.ndarray, ...]: ``voxel`` int64 (truncated towards zero),
        ``step`` (+-1), ``t_max`` and ``t_delta`` float64; Shape (3, N)
        each.
    """
    voxel = start.astype(np.int64)
    step = np.where(unit >= 0, 1, -1)
    moving = unit != 0
    safe = np.where(moving, unit, 1.0)
    big = np.finfo(np.float64).max
    t_max = np.where(moving, (voxel + (step > 0) - start) / safe, big)
    t_delta = np.where(moving, step / safe, big)
    return voxel, step, t_max, t_delta


def _step_axes(t_max: np.ndarray):
    """Which axis each ray crosses next, in the kernel's order at ties
    (z before y before x).

    Args:
        t_max (np.ndarray): Distances to the next boundaries. Shape (3, N).

    Returns:
        tuple[np.ndarray, ...]: bool masks of x, y and z. Shape (N,) each.
    """
    tx, ty, tz = t_max
    on_z = tz <= np.minimum(tx, ty)
    not_z = ~on_z
    return (tx < ty) & not_z, (ty <= tx) & not_z, on_z


def _enter_grid(voxel, step, t_max, t_delta, shape) -> np.ndarray:
    """Walk rays that start outside the grid until they enter it.

    Updates ``voxel`` and ``t_max`` (Shape (3, N)) in place.

    Returns:
        np.ndarray: bool, whether each ray is in the grid now; a ray that
        moves away from it, or needs more than the kernel's step limit,
        never enters. Shape (N,).
    """
    size = np.asarray(shape)[:, None]
    inside = ((voxel >= 0) & (voxel < size)).all(0)
    todo = np.flatnonzero(~inside)
    big = np.finfo(np.float64).max
    for _ in range(_MAX_STEPS):
        v, s = voxel[:, todo], step[:, todo]
        moving = t_delta[:, todo] < big
        stuck = ((v < 0) & ((s < 0) | ~moving)) | \
            ((v >= size) & ((s > 0) | ~moving))
        todo = todo[~stuck.any(0)]
        if not len(todo):
            break
        for axis, mask in enumerate(_step_axes(t_max[:, todo])):
            rows = todo[mask]
            t_max[axis, rows] += t_delta[axis, rows]
            voxel[axis, rows] += step[axis, rows]
        now_in = ((voxel[:, todo] >= 0) & (voxel[:, todo] < size)).all(0)
        inside[todo[now_in]] = True
        todo = todo[~now_in]
    return inside


def _code_grid(grids: Sequence[np.ndarray], free_index: int) -> np.ndarray:
    """Occupancy bits of every grid (bit g: grid g is not free there) with
    a border of :data:`_OUTSIDE` and one parking cell (0) at the end.

    Returns:
        np.ndarray: uint8, flattened. Shape ((X+2) * (Y+2) * (Z+2) + 1,).
    """
    shape = tuple(s + 2 for s in grids[0].shape)
    code = np.full(shape, _OUTSIDE, dtype=np.uint8)
    inner = code[1:-1, 1:-1, 1:-1]
    inner[...] = 0
    for g, grid in enumerate(grids):
        inner |= (grid != free_index).astype(np.uint8) << g
    return np.append(code.ravel(), np.uint8(0))


def _march(code, flat, t_max, t_delta, offsets, num_grids):
    """Traverse all rays at once until each has hit every grid or left.

    Args:
        code (np.ndarray): :func:`_code_grid`. Shape (V + 1,).
        flat (np.ndarray): Flat index of each ray's start voxel in
            ``code``; the parking cell for rays that never enter.
            Shape (N,).
        t_max (np.ndarray): Distance to the next boundary. Shape (3, N).
        t_delta (np.ndarray): Distance between boundaries. Shape (3, N).
        offsets (np.ndarray): Flat index step of each axis. Shape (3, N).
        num_grids (int): G.

    Returns:
        tuple[np.ndarray, np.ndarray]: Flat index (-1: none) and exit
        distance in voxels (NaN: none) of the first occupied voxel of
        every grid. Shape (G, N) each.
    """
    num = len(flat)
    park = len(code) - 1
    hit_flat = np.full((num_grids, num), -1, dtype=np.int64)
    hit_dist = np.full((num_grids, num), np.nan)
    all_grids = np.uint8((1 << num_grids) - 1)
    want = np.full(num, all_grids | _OUTSIDE, dtype=np.uint8)
    want[flat == park] = 0
    offsets[:, want == 0] = 0
    ids = np.arange(num)
    parked = int((want == 0).sum())
    with np.errstate(over='ignore'):
        while len(ids) > parked:
            found = code[flat] & want
            on_x, on_y, on_z = _step_axes(t_max)
            if found.any():
                rows = np.flatnonzero(found)
                bits = found[rows]
                # The exit distance of the current voxel: the next crossing.
                dist = np.minimum(np.minimum(t_max[0, rows], t_max[1, rows]),
                                  t_max[2, rows])
                for g in range(num_grids):
                    pick = (bits >> g) & 1 != 0
                    sel = rows[pick]
                    hit_flat[g, ids[sel]] = flat[sel]
                    hit_dist[g, ids[sel]] = dist[pick]
                left = want[rows] & ~bits
                left[(bits & _OUTSIDE) != 0] = 0
                left[(left & all_grids) == 0] = 0
                want[rows] = left
                done = rows[left == 0]
                flat[done] = park
                offsets[:, done] = 0
                parked += len(done)
                if parked > _COMPACT_SHARE * len(ids):
                    keep = want != 0
                    ids, flat, want = ids[keep], flat[keep], want[keep]
                    t_max, t_delta = t_max[:, keep], t_delta[:, keep]
                    offsets = offsets[:, keep]
                    on_x, on_y, on_z = on_x[keep], on_y[keep], on_z[keep]
                    parked = 0
            # Products with the masks instead of np.where: branch-free and
            # twice as fast; x * 1.0 and x + 0.0 are exact.
            t_max[0] += t_delta[0] * on_x
            t_max[1] += t_delta[1] * on_y
            t_max[2] += t_delta[2] * on_z
            flat += offsets[0] * on_x + offsets[1] * on_y + offsets[2] * on_z
    return hit_flat, hit_dist


def cast_rays(grids: Sequence[np.ndarray],
              origins: np.ndarray,
              directions: Optional[np.ndarray] = None,
              free_index: int = len(OCC3D_CLASS_NAMES) - 1,
              pc_range: Sequence[float] = RAY_PC_RANGE,
              voxel_size: float = RAY_VOXEL_SIZE,
              only: Optional[np.ndarray] = None) -> List[RayHits]:
    """Cast the rays of every origin through one or more label grids.

    All grids are traversed together (the path of a ray is the same in
    each); a ray stops once it has hit every grid or left the grid. A ray
    from an origin outside the grid is followed until it enters.

    Args:
        grids (Sequence[np.ndarray]): At most 7 integer label grids of one
            shape, e.g. ``[pred, gt]``. Shape (X, Y, Z) each.
        origins (np.ndarray): Ray origins in the grid's frame, metres.
            Shape (T, 3).
        directions (np.ndarray, optional): Unit ray directions.
            Shape (R, 3). Defaults to :func:`lidar_ray_directions`.
        free_index (int): Label of free space. Defaults to 17 (Occ3D).
        pc_range (Sequence[float]): Grid extent ``(x0, y0, z0, x1, y1,
            z1)``, metres. Defaults to :data:`RAY_PC_RANGE`.
        voxel_size (float): Voxel edge, metres. Defaults to 0.4.
        only (np.ndarray, optional): bool, cast only these rays (e.g. those
            whose GT, cached, hits something); the others are reported as
            hitting nothing. Shape (T * R,). Defaults to None (all).

    Returns:
        list[RayHits]: One per grid; ray ``t * R + r`` is direction r from
        origin t. Shape (T * R,) each.
    """
    if not 1 <= len(grids) <= _MAX_GRIDS:
        raise ValueError(f'cast_rays: expected 1 to {_MAX_GRIDS} grids, got '
                         f'{len(grids)}.')
    grids = [np.asarray(g) for g in grids]
    shape = grids[0].shape
    if len(shape) != 3 or any(g.shape != shape for g in grids):
        raise ValueError('cast_rays: expected grids of one shape (X, Y, Z), '
                         f'got {[g.shape for g in grids]}.')
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(origins).all():
        raise ValueError(f'cast_rays: origins must be finite, got {origins}.')
    if directions is None:
        directions = lidar_ray_directions()
    start, unit = _voxel_frame(origins, np.asarray(directions), pc_range,
                               voxel_size)
    if not np.isfinite(unit).all():
        raise ValueError('cast_rays: every direction must be finite and '
                         'non-zero.')
    num_rays = start.shape[1]
    cast = np.arange(num_rays)
    if only is not None:
        only = np.asarray(only, dtype=bool).ravel()
        if only.shape != (num_rays, ):
            raise ValueError(f'cast_rays: expected only of shape '
                             f'({num_rays},), got {only.shape}.')
        cast = np.flatnonzero(only)
        start, unit = start[:, cast], unit[:, cast]
    voxel, step, t_max, t_delta = _first_crossings(start, unit)
    inside = _enter_grid(voxel, step, t_max, t_delta, shape)
    code = _code_grid(grids, free_index)
    strides = np.array([[(shape[1] + 2) * (shape[2] + 2)], [shape[2] + 2],
                        [1]])
    flat = np.where(inside, ((voxel + 1) * strides).sum(0), len(code) - 1)
    hit_flat, hit_dist = _march(code, flat, t_max, t_delta, step * strides,
                                len(grids))
    out = []
    size = np.float32(voxel_size)
    for grid, where, dist in zip(grids, hit_flat, hit_dist):
        hit = where >= 0
        label = np.full(num_rays, free_index, dtype=grid.dtype)
        label[cast[hit]] = np.pad(grid, 1).ravel()[where[hit]]
        depth = np.full(num_rays, np.inf, dtype=np.float32)
        depth[cast[hit]] = dist[hit].astype(np.float32) * size
        out.append(RayHits(label, depth))
    return out
