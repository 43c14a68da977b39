"""Sparse per-camera depth maps and 2D semantic maps from LiDAR points.

Both project the points with the current ``lidar2img`` (which includes the
image augmentation, see :mod:`.image_aug`), so the maps are aligned with
the augmented images. The projection, the pixel convention and the nearest
point per pixel are those of :mod:`projects.occ_common.geometry.depth`,
which the models' depth maps and depth bins use too.
"""
from typing import Optional

import numpy as np
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS
from mmengine.logging import print_log

from ..datasets.occ_formats import IGNORE_INDEX
from ..geometry.depth import project_nearest
from .frames import points_xyz
from .point_labels import occupancy_point_labels


def _key_frame(results: dict) -> np.ndarray:
    """Boolean mask of the key-frame points (time lag 0).

    Without merged sweeps (no ``points_time_dim``) every point is a
    key-frame point; column 4 of a raw nuScenes file is the ring index.
    """
    points = results['points']
    time_dim = results.get('points_time_dim')
    if time_dim is None:
        return np.ones(len(points), dtype=bool)
    data = points.tensor.numpy() if hasattr(points, 'tensor') else points
    return data[:, time_dim] == 0


@TRANSFORMS.register_module()
class PointsToDepthMaps(BaseTransform):
    """Sparse depth map per view: depth of the nearest point per pixel.

    The depth supervision of BEVDepth-style view transforms (Li et al.,
    AAAI 2023, Sec. 3.2), at the augmented image resolution. A sample with
    no points gives all-zero maps.

    Args:
        key_frame_only (bool): Use only points with time lag 0 (moving
            objects smear across sweeps); the time column is
            ``points_time_dim``, set by ``LoadOccPointsFromMultiSweeps``.
            Defaults to True.
        min_depth (float): Nearer points are dropped. Defaults to 1e-3.
        max_depth (float, optional): Farther points are dropped.

    Required Keys:

    - points (BasePoints | np.ndarray): Working frame.
    - lidar2img (np.ndarray): (N, 4, 4).
    - img_shape (tuple[int, int]): (H, W).
    - points_time_dim (int, optional): Column of the time lag.

    Added Keys:

    - gt_depth (np.ndarray): Shape (N, H, W), float32, metres; 0 = no
      point.
    """

    def __init__(self,
                 key_frame_only: bool = True,
                 min_depth: float = 1e-3,
                 max_depth: Optional[float] = None) -> None:
        self.key_frame_only = key_frame_only
        self.min_depth = min_depth
        self.max_depth = max_depth

    def transform(self, results: dict) -> dict:
        """Build the depth maps of one sample.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The state with ``gt_depth``.
        """
        height, width = results['img_shape']
        lidar2img = np.asarray(results['lidar2img'])
        xyz = points_xyz(results['points'],
                         _key_frame(results) if self.key_frame_only else None)
        view, row, col, depth, _ = project_nearest(
            xyz, lidar2img, (height, width), self.min_depth, self.max_depth)
        out = np.zeros((len(lidar2img), height, width), np.float32)
        out[view, row, col] = depth
        results['gt_depth'] = out
        return results

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}('
                f'key_frame_only={self.key_frame_only}, '
                f'min_depth={self.min_depth}, '
                f'max_depth={self.max_depth})')


@TRANSFORMS.register_module()
class PointsToSemanticMaps(BaseTransform):
    """2D semantic map per view from the labelled key-frame points.

    Each pixel takes the label of the nearest labelled point projecting
    into it (SDG-OCC's 2D semantic supervision); pixels without one are
    ``ignore_index``. Points whose label is ``ignore_index`` (noise, and
    sweep points after ``LoadOccPointsFromMultiSweeps``) are skipped, so
    they never hide a labelled point behind them.

    The point labels are nuScenes-lidarseg's (``pts_semantic_mask``) when
    the pipeline loaded them. Without lidarseg (the info file has none) the
    key-frame points take the label of the occupancy voxel they fall in
    (``gt_occ``, see :mod:`.point_labels` for why points and not voxel
    rays); the first such sample of a process logs it. With neither (a
    split without labels) no map is made, logged once as well.

    Args:
        ignore_index (int): Label of unlabelled pixels and points.
            Defaults to 255.
        min_depth (float): Nearer points are dropped. Defaults to 1e-3.

    Required Keys:

    - points (BasePoints | np.ndarray): Working frame.
    - pts_semantic_mask (np.ndarray, optional): Shape (P,), aligned with
      points.
    - gt_occ, occ_pc_range, occ_voxel_size (np.ndarray, optional): The
      occupancy labels (``LoadOccupancyGT``), without lidarseg.
    - points_time_dim (int, optional): Column of the time lag.
    - lidar2img (np.ndarray): (N, 4, 4).
    - img_shape (tuple[int, int]): (H, W).

    Added Keys:

    - gt_seg_2d (np.ndarray): Shape (N, H, W), uint8.
    - seg_2d_source (str): ``'lidarseg'`` or ``'occupancy'``.
    """

    def __init__(self,
                 ignore_index: int = IGNORE_INDEX,
                 min_depth: float = 1e-3) -> None:
        self.ignore_index = ignore_index
        self.min_depth = min_depth
        # Per instance, so per dataloader worker: each logs once.
        self._logged = set()

    def transform(self, results: dict) -> dict:
        """Build the semantic maps of one sample.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The state with ``gt_seg_2d``.
        """
        labels = self._point_labels(results)
        if labels is None:
            return results
        height, width = results['img_shape']
        lidar2img = np.asarray(results['lidar2img'])
        if len(labels) != len(results['points']):
            raise ValueError(
                f'pts_semantic_mask has {len(labels)} labels but there are '
                f'{len(results["points"])} points in sample '
                f'{results.get("token", "?")}')
        keep = labels != self.ignore_index
        xyz = points_xyz(results['points'], keep)
        view, row, col, _, index = project_nearest(xyz, lidar2img,
                                                   (height, width),
                                                   self.min_depth)
        out = np.full((len(lidar2img), height, width), self.ignore_index,
                      np.uint8)
        out[view, row, col] = labels[keep][index]
        results['gt_seg_2d'] = out
        return results

    def _point_labels(self, results: dict) -> Optional[np.ndarray]:
        """lidarseg's point labels, else the occupancy grid's, else None.

        Args:
            results (dict): Pipeline state.

        Returns:
            np.ndarray | None: Shape (P,), aligned with ``points``.
        """
        if 'pts_semantic_mask' in results:
            results['seg_2d_source'] = 'lidarseg'
            return np.asarray(results['pts_semantic_mask'])
        if 'gt_occ' not in results:
            self._log_once(
                'no_labels', 'PointsToSemanticMaps: sample '
                f'{results.get("token", "?")} has neither lidarseg nor '
                'occupancy labels: no 2-D semantic targets (gt_seg_2d)')
            return None
        self._log_once(
            'occupancy', 'PointsToSemanticMaps: no nuScenes-lidarseg in '
            f'{results.get("ann_file", "the info file")}: the 2-D semantic '
            'targets come from the occupancy labels (each key-frame point '
            'takes the label of its voxel)')
        results['seg_2d_source'] = 'occupancy'
        key = _key_frame(results)
        labels = np.full(len(key), self.ignore_index, np.int64)
        labels[key] = occupancy_point_labels(
            points_xyz(results['points'], key), results['gt_occ'],
            results['occ_pc_range'], results['occ_voxel_size'],
            self.ignore_index)
        return labels

    def _log_once(self, what: str, message: str) -> None:
        """Log ``message`` the first time ``what`` happens in a process."""
        if what not in self._logged:
            self._logged.add(what)
            print_log(message, logger='current')

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}('
                f'ignore_index={self.ignore_index}, '
                f'min_depth={self.min_depth})')
