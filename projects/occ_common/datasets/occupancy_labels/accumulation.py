"""A scene's returns gathered over its whole sequence.

:func:`accumulate_scene` reads every sweep once and splits its returns
into

* rays (sensor origin and end point, global): every return, also the
  spurious ones, marks the space before it as seen (``mask_lidar``) and
  crossed (free-space carving); so do, for ``mask_lidar`` only, the fired
  rays that returned nothing (:mod:`.no_return`);
* static points (global frame) with their raw lidarseg class where the
  sweep has lidarseg (-1 elsewhere);
* object points in the frame of the box they lie in, one set per
  annotated instance (:mod:`.box_frame`).

Returns lidarseg calls ``noise`` or ``vehicle.ego``, and returns inside
the ego box, are rays but no points.
"""
from dataclasses import dataclass, field
from typing import Dict, List

import numpy as np

from .box_frame import assign_to_boxes, boxes_at
from .config import LabelConfig
from .no_return import firing_pattern, missing_directions, ring_elevations
from .sequence import (RAW_EGO, RAW_GROUND, RAW_NOISE, SceneSequence,
                       read_lidarseg, read_points)


@dataclass
class SweepRays:
    """The returns of one sweep as rays.

    Args:
        origin (np.ndarray): Sensor position, global. Shape (3,).
        ends (np.ndarray): Return positions, global. Shape (R, 3).
        missing (np.ndarray): Unit directions (global) of the fired rays
            without a return. Shape (M, 3).
    """
    origin: np.ndarray
    ends: np.ndarray
    missing: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass
class Accumulation:
    """What :func:`accumulate_scene` gathers.

    Args:
        rays (List[SweepRays]): Per sweep of the scene (same order).
        static_points (np.ndarray): Global. Shape (S, 3).
        static_raw (np.ndarray): Raw lidarseg class, -1 unlabelled, int16.
            Shape (S,).
        static_sweep (np.ndarray): Sweep index of every static point,
            int32. Shape (S,).
        static_dirs (np.ndarray): Unit direction of every static point's
            ray, global, float32. Shape (S, 3).
        objects (Dict[str, np.ndarray]): Box-frame points per instance
            token. Shape (M_i, 3) each.
        object_sweep (Dict[str, np.ndarray]): Sweep index of every object
            point, int32. Shape (M_i,) each.
        object_dirs (Dict[str, np.ndarray]): Unit ray direction of every
            object point, box frame, float32. Shape (M_i, 3) each.
    """
    rays: List[SweepRays]
    static_points: np.ndarray
    static_raw: np.ndarray
    static_sweep: np.ndarray
    static_dirs: np.ndarray
    objects: Dict[str, np.ndarray]
    object_sweep: Dict[str, np.ndarray]
    object_dirs: Dict[str, np.ndarray]


def _transform(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _join(parts: list, empty_shape: tuple, dtype) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros(empty_shape, dtype)


def _rotate_z(vectors: np.ndarray, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * vectors[:, 0] - s * vectors[:, 1],
                     s * vectors[:, 0] + c * vectors[:, 1], vectors[:, 2]],
                    axis=1).astype(np.float32)


def _outside_ego(points_ego: np.ndarray, box) -> np.ndarray:
    lo, hi = np.asarray(box[:3]), np.asarray(box[3:])
    return ~((points_ego >= lo) & (points_ego <= hi)).all(axis=1)


def sweeps_used(scene: SceneSequence, cfg: LabelConfig) -> List[int]:
    """Indices of the sweeps whose points are accumulated (all, or only
    the key frames' for the key-frame-alone baseline)."""
    if cfg.accumulate:
        return list(range(len(scene.sweeps)))
    return [frame.sweep_index for frame in scene.key_frames]


def accumulate_scene(scene: SceneSequence,
                     cfg: LabelConfig) -> Accumulation:
    """Read and split every sweep of a scene (see the module docstring).

    Args:
        scene (SceneSequence): The scene.
        cfg (LabelConfig): Settings (``accumulate``, ``box_frame``, box
            margins, ``ego_box``).

    Returns:
        Accumulation: Rays of every sweep; points of the used ones.
    """
    tracks = list(scene.tracks.values())
    times = np.array([s.timestamp for s in scene.sweeps])
    centers, yaws, valid = boxes_at(tracks, times, cfg.max_extrapolation)
    sizes = np.array([np.median(t.sizes, axis=0) for t in tracks]).reshape(
        -1, 3)
    used = set(sweeps_used(scene, cfg))
    rays, patterns = [], []
    static, raw, sweep_ids, dirs = [], [], [], []
    objects: Dict[str, list] = {t.token: [] for t in tracks}
    for index, sweep in enumerate(scene.sweeps):
        points = read_points(sweep.path)
        labels = None
        if sweep.lidarseg_path is not None:
            labels = read_lidarseg(sweep.lidarseg_path, len(points))
        finite = np.isfinite(points).all(axis=1)
        patterns.append(firing_pattern(points[finite])
                        if cfg.no_return_range > 0 else None)
        points = points[finite, :3].astype(np.float64)
        if labels is not None:
            labels = labels[finite]
        world = _transform(sweep.lidar2global, points)
        rays.append(SweepRays(origin=sweep.lidar2global[:3, 3].copy(),
                              ends=world))
        if index not in used:
            continue
        ego = _transform(np.linalg.inv(sweep.ego2global), world)
        keep = _outside_ego(ego, cfg.ego_box)
        if labels is not None:
            keep &= (labels != RAW_NOISE) & (labels != RAW_EGO)
        world = world[keep]
        point_raw = (labels[keep].astype(np.int16) if labels is not None
                     else np.full(len(world), -1, np.int16))
        ray = world - sweep.lidar2global[:3, 3]
        ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-9)
        owner = np.full(len(world), -1)
        if cfg.box_frame and valid[index].any():
            boxes = np.flatnonzero(valid[index])
            # A point lidarseg calls an object may lie at the very bottom
            # of its box; one it calls ground stays ground, in a box or
            # not; an unlabelled one near a box's bottom is left to the
            # ground.
            ground = np.isin(point_raw, RAW_GROUND)
            clearance = np.where((point_raw >= 0) & ~ground,
                                 -cfg.box_margin, cfg.ground_clearance)
            owner, local = assign_to_boxes(
                world, centers[index, boxes], yaws[index, boxes],
                sizes[boxes], cfg.box_margin, clearance)
            owner[ground] = -1
            for box in np.unique(owner[owner >= 0]):
                mine = owner == box
                objects[tracks[boxes[box]].token].append(
                    (local[mine], np.full(int(mine.sum()), index, np.int32),
                     _rotate_z(ray[mine], -yaws[index, boxes[box]])))
        alone = owner < 0
        static.append(world[alone])
        raw.append(point_raw[alone])
        sweep_ids.append(np.full(int(alone.sum()), index, np.int32))
        dirs.append(ray[alone].astype(np.float32))
    elevations = ring_elevations([p for p in patterns if p is not None])
    for sweep, pattern, ray in zip(scene.sweeps, patterns, rays):
        if pattern is not None:
            ray.missing = missing_directions(
                pattern, elevations) @ sweep.lidar2global[:3, :3].T
    return Accumulation(
        rays=rays,
        static_points=_join(static, (0, 3), np.float64),
        static_raw=_join(raw, (0, ), np.int16),
        static_sweep=_join(sweep_ids, (0, ), np.int32),
        static_dirs=_join(dirs, (0, 3), np.float32),
        objects={token: _join([p[0] for p in parts], (0, 3), np.float64)
                 for token, parts in objects.items()},
        object_sweep={token: _join([p[1] for p in parts], (0, ), np.int32)
                      for token, parts in objects.items()},
        object_dirs={token: _join([p[2] for p in parts], (0, 3), np.float32)
                     for token, parts in objects.items()})
