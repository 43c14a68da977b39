"""One scene's labels: accumulate, carve, label, place, densify, cast.

:func:`scene_labels` yields, key frame by key frame, the label grids of
both formats and the Occ3D visibility masks; :func:`write_scene` writes
them (:mod:`.writers`).
"""
import time
from dataclasses import dataclass
from typing import Dict, Iterator, List, NamedTuple, Tuple

import numpy as np

from .accumulation import Accumulation, accumulate_scene
from .box_frame import from_box_frame
from .config import LabelConfig
from .densification import fill_ground, fill_hull, object_hull
from .free_space import carve, ray_passes, scene_grid
from .semantics import category_label, static_labels
from .sequence import KeyFrame, SceneSequence
from .visibility import camera_mask, lidar_mask
from .voxelization import EMPTY, format_grid, grid_corners, label_grid
from .writers import (occ3d_path, surroundocc_path, write_occ3d,
                      write_surroundocc)

#: The label formats written, and the frame of each one's grid.
FORMATS = ('occ3d', 'surroundocc')


@dataclass
class FrameLabels:
    """The labels of one key frame.

    Args:
        frame (KeyFrame): The key frame.
        occ3d (np.ndarray): uint8 classes 0..16, :data:`.EMPTY` where
            empty, ego frame. Shape (200, 200, 16).
        mask_lidar (np.ndarray): bool. Shape (200, 200, 16).
        mask_camera (np.ndarray): bool. Shape (200, 200, 16).
        surroundocc (np.ndarray): As ``occ3d``, LiDAR frame.
            Shape (200, 200, 16).
    """
    frame: KeyFrame
    occ3d: np.ndarray
    mask_lidar: np.ndarray
    mask_camera: np.ndarray
    surroundocc: np.ndarray


def grid_to_global(frame: KeyFrame, fmt: str) -> np.ndarray:
    """A key frame's grid -> global transform for a format: its ego frame
    (Occ3D) or its LiDAR frame (SurroundOcc). Shape (4, 4)."""
    if fmt == 'occ3d':
        return frame.ego2global
    return frame.ego2global @ frame.lidar2ego


def _transform(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


class _Static(NamedTuple):
    """The static points that survived carving, global: positions
    (S, 3), classes (S,), whether lidarseg labelled them (S,) and their
    rays' unit directions (S, 3)."""
    points: np.ndarray
    labels: np.ndarray
    labelled: np.ndarray
    dirs: np.ndarray

    def subset(self, keep: np.ndarray) -> '_Static':
        return _Static(*(part[keep] for part in self))

    def layers(self, global2grid: np.ndarray,
               depth: float) -> List[Tuple[np.ndarray, np.ndarray]]:
        """Propagated, then lidarseg-labelled points in a grid's frame,
        each ``depth`` metres behind its surface: a voxel with labelled
        points takes their majority, not that of the classes copied to
        its sweeps' points from neighbours."""
        points = _transform(global2grid, self.points + depth * self.dirs)
        return [(points[~self.labelled], self.labels[~self.labelled]),
                (points[self.labelled], self.labels[self.labelled])]


class _Objects:
    """The annotated objects of a scene, ready to be placed."""

    def __init__(self, scene: SceneSequence, acc: Accumulation,
                 cfg: LabelConfig):
        self.scene, self.acc, self.cfg = scene, acc, cfg
        self.labels = {token: category_label(track.category)
                       for token, track in scene.tracks.items()}
        self.hulls = {}
        if cfg.fill_objects and cfg.accumulate:
            self.hulls = {token: object_hull(points)
                          for token, points in acc.objects.items()}

    def at(self, frame: KeyFrame, depth: float
           ) -> Iterator[Tuple[str, np.ndarray, float, np.ndarray]]:
        """``(token, centre, yaw, box-frame points)`` of every instance
        annotated in ``frame`` (only the frame's own points when not
        accumulating), each ``depth`` metres behind its surface."""
        for token in frame.instances:
            track = self.scene.tracks[token]
            k = track.sample_tokens.index(frame.token)
            points = self.acc.objects.get(token, np.zeros((0, 3)))
            dirs = self.acc.object_dirs.get(token, np.zeros((0, 3)))
            if not self.cfg.accumulate:
                own = self.acc.object_sweep[token] == frame.sweep_index
                points, dirs = points[own], dirs[own]
            yield (token, track.centers[k], track.yaws[k],
                   points + depth * dirs)


def _frame_grid(fmt: str, frame: KeyFrame, static: _Static,
                objects: _Objects, cfg: LabelConfig) -> np.ndarray:
    """One format's label grid of a key frame."""
    grid = format_grid(fmt)
    global2grid = np.linalg.inv(grid_to_global(frame, fmt))
    depth = cfg.surface_depth * grid.voxel_size
    object_points, object_labels, placed = [], [], []
    for token, center, yaw, local in objects.at(frame, depth):
        object_points.append(from_box_frame(local, center, yaw))
        object_labels.append(np.full(len(local), objects.labels[token],
                                     np.uint8))
        placed.append((token, center, yaw))
    layers = static.layers(global2grid, depth)
    if object_points:
        layers.append((_transform(global2grid, np.concatenate(
            object_points)), np.concatenate(object_labels)))
    grid_labels = label_grid(grid, layers)
    for token, center, yaw in placed:
        hull = objects.hulls.get(token)
        if hull is not None:
            size = np.median(objects.scene.tracks[token].sizes, axis=0)
            fill_hull(grid_labels, grid, global2grid, hull, center, yaw,
                      size / 2 + cfg.box_margin, objects.labels[token])
    return fill_ground(grid_labels, grid.voxel_size, cfg.ground_fill_radius)


def scene_labels(scene: SceneSequence,
                 cfg: LabelConfig) -> Iterator[FrameLabels]:
    """The labels of every key frame of a scene.

    Args:
        scene (SceneSequence): The scene.
        cfg (LabelConfig): Settings.

    Yields:
        FrameLabels: One per key frame, in time order.
    """
    acc = accumulate_scene(scene, cfg)
    extents = [grid_corners(format_grid(fmt), grid_to_global(frame, fmt))
               for frame in scene.key_frames for fmt in FORMATS]
    keep = np.ones(len(acc.static_points), dtype=bool)
    if len(keep) and extents:
        world = scene_grid(extents, cfg.carve_voxel)
        keep = carve(world, acc.static_points, ray_passes(world, acc.rays),
                     cfg.min_hit_ratio)
    points, raw = acc.static_points[keep], acc.static_raw[keep]
    sweep = acc.static_sweep[keep]
    all_static = _Static(points, static_labels(points, raw,
                                               cfg.label_radius),
                         raw >= 0, acc.static_dirs[keep])
    objects = _Objects(scene, acc, cfg)
    occ3d_grid = format_grid('occ3d')
    for frame in scene.key_frames:
        static = all_static if cfg.accumulate else all_static.subset(
            sweep == frame.sweep_index)
        occ3d = _frame_grid('occ3d', frame, static, objects, cfg)
        global2ego = np.linalg.inv(frame.ego2global)
        first = max(0, frame.sweep_index - cfg.mask_sweeps + 1)
        mask_lidar = lidar_mask(occ3d_grid, global2ego,
                                acc.rays[first:frame.sweep_index + 1],
                                cfg.no_return_range)
        mask_camera = camera_mask(occ3d_grid, occ3d != EMPTY, frame.cameras,
                                  global2ego, cfg.camera_ray_spacing)
        yield FrameLabels(
            frame=frame, occ3d=occ3d, mask_lidar=mask_lidar,
            mask_camera=mask_camera,
            surroundocc=_frame_grid('surroundocc', frame, static, objects,
                                    cfg))


def write_scene(scene: SceneSequence, out_dir: str,
                cfg: LabelConfig) -> Dict[str, object]:
    """Write the labels of every key frame of a scene.

    Args:
        scene (SceneSequence): The scene.
        out_dir (str): Output root (``gts/`` and ``nuscenes_occ/``).
        cfg (LabelConfig): Settings.

    Returns:
        dict: ``scene``, ``key_frames``, ``files`` (written) and
        ``seconds``.
    """
    start = time.time()
    files: List[str] = []
    for labels in scene_labels(scene, cfg):
        frame = labels.frame
        files.append(write_occ3d(
            occ3d_path(out_dir, scene.name, frame.token), labels.occ3d,
            labels.mask_lidar, labels.mask_camera))
        files.append(write_surroundocc(
            surroundocc_path(out_dir, frame.lidar_file), labels.surroundocc))
    return dict(scene=scene.name, key_frames=len(scene.key_frames),
                files=files, seconds=round(time.time() - start, 2))
