"""Vectorised ray casting against the ground plane and oriented boxes.

Shared by the cameras (one ray per pixel) and the LiDAR (one ray per beam
and azimuth step), so both see exactly the same geometry. Rays leave one
origin; each box is tested only against its candidate rays (the pixels its
projection covers, the azimuth columns it spans), which keeps the cost
proportional to the image area objects cover instead of pixels x boxes.

Box intersection uses the slab method in the box's frame: a ray
``o + t d`` is inside the box for ``t`` in ``[max_i t_near_i, min_i
t_far_i]`` with ``t_near_i, t_far_i`` the entry / exit distances of the
slab ``|x_i| <= size_i / 2``.
"""
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

#: ``RayHits.target`` of rays that hit the ground plane.
TARGET_GROUND = -1
#: ``RayHits.target`` of rays that hit nothing (sky, beyond range).
TARGET_NONE = -2


@dataclass
class RayHits:
    """Nearest hit of every ray.

    Args:
        t (np.ndarray): Ray parameter of the hit (the distance for unit
            directions), ``np.inf`` where nothing was hit. Shape (R,).
        target (np.ndarray): Box index of the hit, :data:`TARGET_GROUND` or
            :data:`TARGET_NONE`. Shape (R,).
        normal (np.ndarray): Unit surface normal at the hit, global frame;
            zeros where nothing was hit. Shape (R, 3).
        box_ray_counts (np.ndarray): Rays that intersect each box ignoring
            occlusion (its unoccluded projected area, in rays).
            Shape (N,).
    """
    t: np.ndarray
    target: np.ndarray
    normal: np.ndarray
    box_ray_counts: np.ndarray

    def points(self, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Global hit points ``origin + t * dir`` (inf where no hit).

        Args:
            origin (np.ndarray): Ray origin. Shape (3,).
            dirs (np.ndarray): Ray directions. Shape (R, 3).

        Returns:
            np.ndarray: Hit points. Shape (R, 3).
        """
        with np.errstate(invalid='ignore'):
            return origin + self.t[:, None] * dirs


def _safe_inverse(values: np.ndarray) -> np.ndarray:
    """``1 / values`` with zeros replaced by a tiny signed number, so that a
    ray parallel to a slab gets +-inf-like distances instead of NaN."""
    tiny = np.where(values >= 0, 1e-12, -1e-12)
    return 1.0 / np.where(np.abs(values) < 1e-12, tiny, values)


def cast_rays(origin: np.ndarray,
              dirs: np.ndarray,
              centers: np.ndarray,
              sizes: np.ndarray,
              yaws: np.ndarray,
              candidates: Optional[Sequence[Optional[np.ndarray]]] = None,
              t_min: float = 1e-6,
              t_max: float = np.inf,
              ground: bool = True) -> RayHits:
    """Casts rays from one origin against the ground ``z = 0`` and boxes.

    Args:
        origin (np.ndarray): Ray origin, global frame. Shape (3,).
        dirs (np.ndarray): Ray directions (any length; ``t`` is measured in
            multiples of it). Shape (R, 3).
        centers (np.ndarray): Box centres. Shape (N, 3).
        sizes (np.ndarray): Box length, width, height. Shape (N, 3).
        yaws (np.ndarray): Box headings. Shape (N,).
        candidates (Sequence[Optional[np.ndarray]], optional): For every
            box, the indices of the rays that may hit it (None: all rays;
            an empty array skips the box). Defaults to None (all rays for
            all boxes).
        t_min (float): Hits closer than this are ignored. Defaults to 1e-6.
        t_max (float): Hits farther than this are ignored.
            Defaults to inf.
        ground (bool): Whether to intersect the ground plane.
            Defaults to True.

    Returns:
        RayHits: The nearest hit of every ray.
    """
    origin = np.asarray(origin, dtype=np.float64)
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    num_rays, num_boxes = len(dirs), len(yaws)
    best_t = np.full(num_rays, np.inf)
    target = np.full(num_rays, TARGET_NONE, dtype=np.int64)
    normal = np.zeros((num_rays, 3))
    if ground and origin[2] > 0:
        down = dirs[:, 2] < 0
        t_ground = np.full(num_rays, np.inf)
        t_ground[down] = -origin[2] / dirs[down, 2]
        valid = down & (t_ground >= t_min) & (t_ground <= t_max)
        best_t[valid] = t_ground[valid]
        target[valid] = TARGET_GROUND
        normal[valid, 2] = 1.0
    counts = np.zeros(num_boxes, dtype=np.int64)
    for box in range(num_boxes):
        index = None if candidates is None else candidates[box]
        if index is not None and len(index) == 0:
            continue
        d = dirs if index is None else dirs[index]
        c, s = np.cos(yaws[box]), np.sin(yaws[box])
        delta = origin - centers[box]
        o_local = np.array([c * delta[0] + s * delta[1],
                            -s * delta[0] + c * delta[1], delta[2]])
        d_local = np.stack([c * d[:, 0] + s * d[:, 1],
                            -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
        inverse = _safe_inverse(d_local)
        half = sizes[box] / 2.0
        t_lo = (-half - o_local) * inverse
        t_hi = (half - o_local) * inverse
        t_entry = np.minimum(t_lo, t_hi)
        axis = np.argmax(t_entry, axis=1)
        t_near = np.take_along_axis(t_entry, axis[:, None], axis=1)[:, 0]
        t_far = np.maximum(t_lo, t_hi).min(axis=1)
        hit = (t_near <= t_far) & (t_near >= t_min) & (t_near <= t_max)
        counts[box] = int(hit.sum())
        rays = np.nonzero(hit)[0] if index is None else index[hit]
        closer = t_near[hit] < best_t[rays]
        if not closer.any():
            continue
        rays = rays[closer]
        hit_axis = axis[hit][closer]
        best_t[rays] = t_near[hit][closer]
        target[rays] = box
        # The entry face's outward normal points against the ray.
        sign = -np.sign(d_local[hit][closer, hit_axis])
        n_local = np.zeros((len(rays), 3))
        n_local[np.arange(len(rays)), hit_axis] = sign
        normal[rays, 0] = c * n_local[:, 0] - s * n_local[:, 1]
        normal[rays, 1] = s * n_local[:, 0] + c * n_local[:, 1]
        normal[rays, 2] = n_local[:, 2]
    return RayHits(t=best_t, target=target, normal=normal,
                   box_ray_counts=counts)


def cone_candidates(origin: np.ndarray, corners: np.ndarray,
                    num_rows: int, row_angles: np.ndarray,
                    num_cols: int, col_offset: float,
                    sensor_yaw: float) -> list:
    """Candidate rays of every box for a spinning sensor's (row, column)
    ray grid, from each box's bounding circle and height range.

    Rays are laid out row-major: ray ``r * num_cols + c`` has elevation
    ``row_angles[r]`` and azimuth ``col_offset + c * 2 pi / num_cols``
    (relative to ``sensor_yaw``). The bounds are conservative: a box's
    azimuth span is taken from its bounding circle, its elevation span from
    the nearest and farthest distance to that circle.

    Args:
        origin (np.ndarray): Sensor position, global. Shape (3,).
        corners (np.ndarray): Box corners, global. Shape (N, 8, 3).
        num_rows (int): Rows (beams) of the ray grid.
        row_angles (np.ndarray): Elevation of every row, radians.
            Shape (num_rows,).
        num_cols (int): Columns (azimuth steps) of the ray grid.
        col_offset (float): Azimuth of column 0 relative to
            ``sensor_yaw``, radians.
        sensor_yaw (float): Global yaw of the sensor's azimuth zero.

    Returns:
        list: For every box, an int64 array of candidate ray indices (None
        for "all rays").
    """
    center = corners.mean(axis=1)
    delta = center[:, :2] - origin[:2]
    dist = np.hypot(delta[:, 0], delta[:, 1])
    radius = np.linalg.norm(corners[:, :, :2] - center[:, None, :2],
                            axis=2).max(axis=1)
    z_lo = corners[:, :, 2].min(axis=1) - origin[2]
    z_hi = corners[:, :, 2].max(axis=1) - origin[2]
    near = np.maximum(dist - radius, 1e-3)
    far = dist + radius
    elev_hi = np.arctan2(z_hi, np.where(z_hi > 0, near, far))
    elev_lo = np.arctan2(z_lo, np.where(z_lo < 0, near, far))
    step = 2 * np.pi / num_cols
    azimuth = np.arctan2(delta[:, 1], delta[:, 0]) - sensor_yaw - col_offset
    result = []
    for box in range(len(corners)):
        rows = np.nonzero((row_angles >= elev_lo[box] - 1e-6)
                          & (row_angles <= elev_hi[box] + 1e-6))[0]
        if len(rows) == 0:
            result.append(np.zeros(0, dtype=np.int64))
            continue
        if dist[box] <= radius[box] + 0.5:
            cols = np.arange(num_cols)
        else:
            half = np.arcsin(min(1.0, radius[box] / dist[box]))
            lo = int(np.floor((azimuth[box] - half) / step))
            hi = int(np.ceil((azimuth[box] + half) / step))
            cols = np.arange(lo, hi + 1) % num_cols
        result.append((rows[:, None] * num_cols + cols[None]).ravel())
    return result
