"""Working-frame bookkeeping shared by the transforms, and PointsToEgoFrame.

Convention of every pipeline of this library: ``points`` and the occupancy
grid live in one *working frame*, called "lidar" in the key names
(``lidar2cam``, ``lidar2img``, ``lidar2ego``) as in mmdet3d. The per-camera
matrices are stacked arrays, shape (N, 4, 4), mapping column vectors:

* ``cam2img``: the 3x3 intrinsics padded to 4x4;
* ``img_aug_matrix``: the image augmentation (pixel to pixel, identity
  before any);
* ``lidar2cam``: working frame to camera;
* ``lidar2img = img_aug_matrix @ cam2img @ lidar2cam``, kept up to date by
  :func:`refresh_lidar2img` after any transform changes a factor.
"""
from typing import Optional, Union

import numpy as np
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS
from mmdet3d.structures.points import BasePoints

PointsType = Union[BasePoints, np.ndarray]


def points_xyz(points: PointsType,
               mask: Optional[np.ndarray] = None) -> np.ndarray:
    """The coordinates of ``points`` (optionally a subset) as float64.

    Args:
        points (BasePoints | np.ndarray): Shape (P, C), C >= 3.
        mask (np.ndarray, optional): Boolean, shape (P,): rows to take.

    Returns:
        np.ndarray: Shape (P', 3).
    """
    data = points.tensor.numpy() if isinstance(points, BasePoints) \
        else np.asarray(points)
    xyz = data[:, :3] if mask is None else data[mask, :3]
    return xyz.astype(np.float64)


def transform_points(points: PointsType, matrix: np.ndarray) -> PointsType:
    """Apply a 4x4 affine transform to the coordinates of ``points``.

    Works in place (the pipeline owns its points) in the points' own dtype;
    columns after x, y, z (intensity, time lag, ...) are kept.

    Args:
        points (BasePoints | np.ndarray): Shape (P, C).
        matrix (np.ndarray): Shape (4, 4), maps column vectors.

    Returns:
        BasePoints | np.ndarray: ``points``, transformed.
    """
    matrix = np.asarray(matrix, dtype=np.float64)
    # A numpy view of the tensor: numpy's small matmul does not contend for
    # threads the way torch's does on a busy CPU.
    data = points.tensor.numpy() if isinstance(points, BasePoints) \
        else points
    data[:, :3] = data[:, :3] @ matrix[:3, :3].T.astype(
        data.dtype) + matrix[:3, 3].astype(data.dtype)
    return points


def refresh_lidar2img(results: dict) -> None:
    """Recompute ``lidar2img`` from its three factors (in place).

    Args:
        results (dict): Holds ``cam2img``, ``lidar2cam`` (N, 4, 4) and
            optionally ``img_aug_matrix`` (N, 4, 4).
    """
    lidar2img = results['cam2img'] @ results['lidar2cam']
    if 'img_aug_matrix' in results:
        lidar2img = results['img_aug_matrix'] @ lidar2img
    results['lidar2img'] = lidar2img


def change_working_frame(results: dict, old2new: np.ndarray) -> None:
    """Re-express points and every ``lidar2*`` matrix in a new frame.

    A point keeps its meaning: ``lidar2X_new = lidar2X_old @ new2old``.

    Args:
        results (dict): Pipeline state; ``points``, ``lidar2cam``,
            ``lidar2ego`` are updated when present, ``lidar2img`` refreshed.
        old2new (np.ndarray): Shape (4, 4).
    """
    new2old = np.linalg.inv(old2new)
    if 'points' in results:
        results['points'] = transform_points(results['points'], old2new)
    for key in ('lidar2cam', 'lidar2ego'):
        if key in results:
            results[key] = np.asarray(results[key]) @ new2old
    if 'cam2img' in results and 'lidar2cam' in results:
        refresh_lidar2img(results)


@TRANSFORMS.register_module()
class PointsToEgoFrame(BaseTransform):
    """Make the ego frame of the key frame the working frame.

    Occ3D labels are in the ego frame, so for them the LiDAR points (key
    frame and merged sweeps) and all ``lidar2*`` matrices are rewritten with
    ``lidar2ego``; afterwards "lidar" in key names means the ego frame and
    ``lidar2ego`` is the identity. Apply it after the points (and sweeps)
    and images are loaded, before any BEV augmentation.

    Required Keys:

    - lidar2ego (np.ndarray): Shape (4, 4).
    - points (BasePoints | np.ndarray, optional)
    - lidar2cam, cam2img, img_aug_matrix (np.ndarray, optional): (N, 4, 4).

    Modified Keys:

    - points, lidar2cam, lidar2img, lidar2ego (now the identity)

    Added Keys:

    - ori_lidar2ego (np.ndarray): The sensor's lidar2ego, shape (4, 4).
    - coord_frame (str): ``'ego'``.
    """

    def transform(self, results: dict) -> dict:
        """Move the sample into the ego frame.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The updated state.
        """
        if 'ori_lidar2ego' in results:
            raise ValueError('PointsToEgoFrame applied twice to sample '
                             f'{results.get("token")}')
        lidar2ego = np.asarray(results['lidar2ego'], dtype=np.float64)
        results['ori_lidar2ego'] = lidar2ego
        change_working_frame(results, lidar2ego)
        results['coord_frame'] = 'ego'
        return results

    def __repr__(self) -> str:
        """str: The transform and its (no) arguments."""
        return f'{self.__class__.__name__}()'
