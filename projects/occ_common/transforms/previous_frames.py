"""LoadPreviousKeyFrames: the earlier key frames of a temporal sample.

A T-frame model (SDG-OCC Sec. 3.1, BEVDet4D) sees the current key frame
and the T - 1 before it. This transform runs after the current frame's
images, BEV augmentation and working-frame change, and adds the previous
frames as the model expects them (see :mod:`projects.sdg_occ.
temporal_fusion`): their views after the current ones in ``img``, their
camera matrices in their own working frame, and ``prev2curr``, the map
from each previous working frame to the current one.

Every frame gets the current frame's augmentation, as BEVDet4D does: the
image augmentation parameters of each view, and the BEV augmentation
``bda``, so each previous working frame is ``bda @ W`` of its own sensor
frame, ``W`` being the identity (LiDAR working frame) or the frame's own
``lidar2ego`` (after ``PointsToEgoFrame``).
"""
from typing import Optional, Sequence

import numpy as np
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS

from .ego_points import in_ego_box
from .image_aug import augment_view
from .image_loading import LoadMultiViewImagesOcc
from .points_loading import read_points_file


@TRANSFORMS.register_module()
class LoadPreviousKeyFrames(BaseTransform):
    """Load the T - 1 previous key frames of a sample.

    The first key frame of a scene repeats itself (the dataset's
    ``prev_frames`` then hold the current frame): a car that has not moved.

    Args:
        num_frames (int): T >= 2, the current frame included.
        load_points (bool): Also load each previous key frame's LiDAR
            points (for a view transform guided by LiDAR depth, SDG-OCC's).
            Defaults to False.
        ego_box (Sequence[float], optional): Drop the previous frames'
            points in this ego-frame box, as ``RemoveEgoPoints`` does for
            the current frame. Defaults to None (keep them).
        point_cloud_range (Sequence[float], optional): Keep the previous
            frames' points strictly inside it (working frame), as
            ``PointsRangeFilter`` does. Defaults to None (keep all).
        backend_args (dict, optional): mmengine file backend arguments.
        scale_calibration (bool): As :class:`LoadMultiViewImagesOcc`.
            Defaults to False.

    Required Keys:

    - prev_frames (list[dict]): From ``NuScenesOccDataset(num_frames=T)``;
      per frame ``token``, ``ego2global``, ``lidar2ego``, ``lidar_path``,
      ``num_pts_feats``, ``images``.
    - img (list[np.ndarray]), cam_names, img_shape, img_aug_matrix
      (N, 4, 4), ego2global, lidar2ego (4, 4, the working frame's), and
      optionally img_aug_params, bda_matrix, ori_lidar2ego.

    Modified Keys:

    - img: N * T views, the current frame's first.

    Added Keys:

    - prev_tokens (list[str]): T - 1 tokens, nearest first.
    - prev2curr (np.ndarray): Shape (T - 1, 4, 4).
    - prev_cam2img, prev_lidar2cam, prev_img_aug_matrix, prev_lidar2img
      (np.ndarray): Shape (T - 1, N, 4, 4).
    - prev_points (list[np.ndarray]): T - 1 arrays (P, C), only with
      ``load_points``.
    """

    def __init__(self,
                 num_frames: int,
                 load_points: bool = False,
                 ego_box: Optional[Sequence[float]] = None,
                 point_cloud_range: Optional[Sequence[float]] = None,
                 backend_args: Optional[dict] = None,
                 scale_calibration: bool = False) -> None:
        if num_frames < 2:
            raise ValueError('LoadPreviousKeyFrames needs num_frames >= 2, '
                             f'got {num_frames}')
        self.num_frames = int(num_frames)
        self.load_points = load_points
        # The same point filters as the current frame's: a frame's camera
        # BEV is then the same whether it is computed as the current frame
        # or as a previous one, which the test-time cache relies on.
        self.ego_box = None if ego_box is None else list(ego_box)
        self.point_cloud_range = (None if point_cloud_range is None else
                                  np.asarray(point_cloud_range, np.float64))
        self.backend_args = backend_args
        self.scale_calibration = scale_calibration

    def _sensor_to_working(self, results: dict,
                           lidar2ego: np.ndarray) -> np.ndarray:
        """``bda @ W`` of a frame whose sensor has ``lidar2ego``."""
        bda = np.asarray(results.get('bda_matrix', np.eye(4)), np.float64)
        if 'ori_lidar2ego' in results:  # the working frame is the ego's
            return bda @ np.asarray(lidar2ego, np.float64)
        return bda

    def transform(self, results: dict) -> dict:
        """Append the previous frames.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The state with the added keys.
        """
        token = results.get('token', '?')
        frames = results.get('prev_frames')
        if frames is None or len(frames) < self.num_frames - 1:
            raise ValueError(
                f'sample {token}: LoadPreviousKeyFrames(num_frames='
                f'{self.num_frames}) needs {self.num_frames - 1} prev_frames;'
                f' got {None if frames is None else len(frames)}. Build the '
                f'dataset with num_frames={self.num_frames}.')
        loader = LoadMultiViewImagesOcc(
            cam_names=results['cam_names'],
            backend_args=self.backend_args,
            scale_calibration=self.scale_calibration)
        params = results.get('img_aug_params')
        aug = np.asarray(results['img_aug_matrix'], np.float64)
        curr2global = (np.asarray(results['ego2global'], np.float64)
                       @ np.asarray(results['lidar2ego'], np.float64))
        imgs = list(results['img'])
        out = dict(prev_tokens=[], prev2curr=[], prev_cam2img=[],
                   prev_lidar2cam=[], prev_img_aug_matrix=[],
                   prev_lidar2img=[])
        points = []
        for frame in frames[:self.num_frames - 1]:
            views = loader(dict(images=frame['images'], token=frame['token']))
            for i, img in enumerate(views['img']):
                if params is not None:
                    img = augment_view(img, params[i], results['img_shape'])[0]
                imgs.append(img)
            to_work = self._sensor_to_working(results, frame['lidar2ego'])
            from_work = np.linalg.inv(to_work)
            lidar2cam = views['lidar2cam'] @ from_work
            prev2global = (np.asarray(frame['ego2global'], np.float64)
                           @ np.asarray(frame['lidar2ego'], np.float64)
                           @ from_work)
            out['prev_tokens'].append(frame['token'])
            out['prev2curr'].append(np.linalg.inv(curr2global) @ prev2global)
            out['prev_cam2img'].append(views['cam2img'])
            out['prev_lidar2cam'].append(lidar2cam)
            out['prev_img_aug_matrix'].append(aug)
            out['prev_lidar2img'].append(aug @ views['cam2img'] @ lidar2cam)
            if self.load_points:
                pts = read_points_file(
                    frame['lidar_path'], int(frame['num_pts_feats']),
                    f'LiDAR points of key frame {frame["token"]}',
                    self.backend_args)
                points.append(self._previous_points(pts, frame, to_work))
        results['img'] = imgs
        for key, value in out.items():
            results[key] = value if key == 'prev_tokens' else np.stack(value)
        if self.load_points:
            results['prev_points'] = points
        return results

    def _previous_points(self, pts: np.ndarray, frame: dict,
                         to_work: np.ndarray) -> np.ndarray:
        """A previous frame's points (P, C) in its working frame, with the
        current frame's filters."""
        if self.ego_box is not None:
            pts = pts[~in_ego_box(pts[:, :3], frame['lidar2ego'],
                                  self.ego_box)]
        xyz = pts[:, :3].astype(np.float64) @ to_work[:3, :3].T \
            + to_work[:3, 3]
        pts[:, :3] = xyz.astype(np.float32)
        if self.point_cloud_range is not None:
            lo, hi = self.point_cloud_range[:3], self.point_cloud_range[3:]
            inside = np.all((pts[:, :3] > lo) & (pts[:, :3] < hi), axis=1)
            pts = pts[inside]
        return pts

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}(num_frames={self.num_frames}, '
                f'load_points={self.load_points}, '
                f'ego_box={self.ego_box}, '
                f'point_cloud_range={self.point_cloud_range}, '
                f'scale_calibration={self.scale_calibration})')
