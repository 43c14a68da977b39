"""Resize / crop / flip / rotate augmentation of multi-view images.

The augmentation of each view is one 2D affine map ``A`` of pixel
coordinates (BEVDet's image-view augmentation, Huang et al. 2021, Sec. 3.3,
written as a single matrix). Pixel ``i`` covers ``[i, i + 1)``, so
resizing is a pure scale, a horizontal flip is ``u -> W - u`` and rotation
turns about ``(W / 2, H / 2)``. ``A`` is kept as a 4x4 ``img_aug_matrix``
acting on the homogeneous image point ``(u d, v d, d, 1)``: its translation
sits in column 2 because it must scale with the depth ``d``. Hence
``lidar2img = img_aug_matrix @ cam2img @ lidar2cam`` projects straight into
the augmented image.
"""
import math
from typing import Sequence, Tuple

import cv2
import numpy as np
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS

from .frames import refresh_lidar2img


def _affine(scale_x: float, scale_y: float, crop: Tuple[float, float],
            flip: bool, angle_deg: float, size: Tuple[int, int]) -> np.ndarray:
    """3x3 pixel map: scale, then crop, then flip, then rotate."""
    height, width = size
    mat = np.diag([scale_x, scale_y, 1.0])
    mat = np.array([[1, 0, -crop[0]], [0, 1, -crop[1]], [0, 0, 1]]) @ mat
    if flip:
        mat = np.array([[-1, 0, width], [0, 1, 0], [0, 0, 1]]) @ mat
    if angle_deg:
        theta = math.radians(angle_deg)
        cos, sin = math.cos(theta), math.sin(theta)
        centre = np.array([width / 2, height / 2])
        rot = np.eye(3)
        rot[:2, :2] = [[cos, -sin], [sin, cos]]
        rot[:2, 2] = centre - rot[:2, :2] @ centre
        mat = rot @ mat
    return mat


def affine_to_4x4(mat: np.ndarray) -> np.ndarray:
    """Embed a 3x3 pixel affine map as an ``img_aug_matrix``.

    Args:
        mat (np.ndarray): Shape (3, 3), maps (u, v, 1).

    Returns:
        np.ndarray: Shape (4, 4), maps (u d, v d, d, 1).
    """
    out = np.eye(4)
    out[:2, :2] = mat[:2, :2]
    out[:2, 2] = mat[:2, 2]
    return out


def augment_view(img: np.ndarray, params: dict,
                 final_size: Tuple[int, int]) -> tuple:
    """Apply one view's augmentation parameters.

    Shared by :class:`MultiViewImageAug` and the previous key frames of a
    temporal sample, which take the current frame's parameters.

    Args:
        img (np.ndarray): Shape (H0, W0, C).
        params (dict): ``resized``, ``crop``, ``flip``, ``rotate``, from
            :meth:`MultiViewImageAug.sample_params`.
        final_size (tuple[int, int]): Output (H, W).

    Returns:
        tuple[np.ndarray, np.ndarray]: The image (H, W, C) and its 3x3
        pixel map.
    """
    height, width = final_size
    src_h, src_w = img.shape[:2]
    res_h, res_w = params['resized']
    # The rounded size fixes the exact (possibly anisotropic) scale.
    scale_x, scale_y = res_w / src_w, res_h / src_h
    if (res_h, res_w) != (src_h, src_w):
        shrink = res_w < src_w
        img = cv2.resize(
            img, (res_w, res_h),
            interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    full = _affine(scale_x, scale_y, params['crop'], params['flip'],
                   params['rotate'], final_size)
    rest = _affine(1.0, 1.0, params['crop'], params['flip'],
                   params['rotate'], final_size)
    # OpenCV puts pixel centres at integers: shift by half a pixel.
    half = np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1]])
    warp = np.linalg.inv(half) @ rest @ half
    out = cv2.warpAffine(
        img,
        warp[:2],
        (width, height),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0)
    if out.ndim == 2 and img.ndim == 3:
        out = out[..., None]
    return out, full


@TRANSFORMS.register_module()
class MultiViewImageAug(BaseTransform):
    """Resize, crop, flip and rotate every view; track the pixel map.

    The base scale ``s0 = max(H / H0, W / W0)`` makes the resized view
    cover the output (``final_size`` (H, W) from a view of size (H0, W0));
    training draws ``s = s0 * U(resize_range)``, the crop position as a
    fraction of the slack ``U(crop_x_range)``, ``U(crop_y_range)`` (0 =
    left / top, 1 = right / bottom), a flip with ``flip_prob`` and an
    angle ``U(rot_range)`` in degrees, independently per view. In
    ``test_mode`` every range is replaced by its midpoint and nothing is
    flipped. Pixels from outside the source are 0.

    Args:
        final_size (Sequence[int]): Output (H, W).
        resize_range (Sequence[float]): Scale multiplier range.
            Defaults to (1.0, 1.0).
        crop_x_range (Sequence[float]): Horizontal crop position range.
            Defaults to (0.0, 1.0).
        crop_y_range (Sequence[float]): Vertical crop position range.
            Defaults to (1.0, 1.0): keep the bottom, where the road is
            (nuScenes' top rows are mostly sky).
        flip_prob (float): Horizontal flip probability. Defaults to 0.5.
        rot_range (Sequence[float]): Rotation range in degrees.
            Defaults to (-5.4, 5.4) (BEVDet's).
        test_mode (bool): Deterministic midpoints. Defaults to False.

    Required Keys:

    - img (list[np.ndarray]): N views, each (H0, W0, C).
    - cam2img, lidar2cam, img_aug_matrix (np.ndarray): (N, 4, 4).

    Modified Keys:

    - img: each (H, W, C).
    - img_shape, pad_shape (tuple[int, int]): (H, W).
    - img_aug_matrix: ``A_new @ A_old`` per view.
    - lidar2img (np.ndarray): (N, 4, 4), recomputed.

    Added Keys:

    - img_aug_params (list[dict]): Per view ``scale``, ``crop``, ``flip``,
      ``rotate`` (degrees).
    """

    def __init__(self,
                 final_size: Sequence[int],
                 resize_range: Sequence[float] = (1.0, 1.0),
                 crop_x_range: Sequence[float] = (0.0, 1.0),
                 crop_y_range: Sequence[float] = (1.0, 1.0),
                 flip_prob: float = 0.5,
                 rot_range: Sequence[float] = (-5.4, 5.4),
                 test_mode: bool = False) -> None:
        if len(final_size) != 2 or min(final_size) < 1:
            raise ValueError(f'final_size must be (H, W) > 0, got '
                             f'{final_size}')
        for name, rng in (('resize_range', resize_range),
                          ('crop_x_range', crop_x_range),
                          ('crop_y_range', crop_y_range),
                          ('rot_range', rot_range)):
            if len(rng) != 2 or rng[0] > rng[1]:
                raise ValueError(f'{name} must be (low, high), got {rng}')
        if resize_range[0] <= 0:
            raise ValueError(f'resize_range must be > 0, got {resize_range}')
        self.final_size = tuple(int(v) for v in final_size)
        self.resize_range = tuple(resize_range)
        self.crop_x_range = tuple(crop_x_range)
        self.crop_y_range = tuple(crop_y_range)
        self.flip_prob = flip_prob
        self.rot_range = tuple(rot_range)
        self.test_mode = test_mode

    def _draw(self, rng: Tuple[float, float]) -> float:
        if self.test_mode:
            return (rng[0] + rng[1]) / 2
        return float(np.random.uniform(*rng))

    def sample_params(self, src_size: Tuple[int, int]) -> dict:
        """Draw the augmentation of one view.

        Args:
            src_size (tuple[int, int]): Source (H0, W0).

        Returns:
            dict: ``resized`` (H', W'), ``crop`` (x, y) offset in the
            resized image, ``flip`` (bool), ``rotate`` (degrees).
        """
        height, width = self.final_size
        base = max(height / src_size[0], width / src_size[1])
        scale = base * self._draw(self.resize_range)
        resized = (max(1, round(src_size[0] * scale)),
                   max(1, round(src_size[1] * scale)))
        crop = (self._draw(self.crop_x_range) * (resized[1] - width),
                self._draw(self.crop_y_range) * (resized[0] - height))
        crop = (float(round(crop[0])), float(round(crop[1])))
        flip = (not self.test_mode) and np.random.rand() < self.flip_prob
        return dict(
            resized=resized,
            crop=crop,
            flip=bool(flip),
            rotate=self._draw(self.rot_range))

    def augment(self, img: np.ndarray, params: dict) -> tuple:
        """Apply one view's augmentation (:func:`augment_view`).

        Args:
            img (np.ndarray): Shape (H0, W0, C).
            params (dict): From :meth:`sample_params`.

        Returns:
            tuple[np.ndarray, np.ndarray]: The image (H, W, C) and its 3x3
            pixel map.
        """
        return augment_view(img, params, self.final_size)

    def transform(self, results: dict) -> dict:
        """Augment every view of one sample.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The state with augmented views and matrices.
        """
        imgs, params_all, mats = [], [], []
        for img in results['img']:
            params = self.sample_params(img.shape[:2])
            out, mat = self.augment(img, params)
            imgs.append(out)
            params_all.append(params)
            mats.append(affine_to_4x4(mat))
        results['img'] = imgs
        results['img_shape'] = results['pad_shape'] = self.final_size
        results['img_aug_params'] = params_all
        if mats:
            results['img_aug_matrix'] = np.stack(mats) @ results[
                'img_aug_matrix']
        refresh_lidar2img(results)
        return results

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}(final_size={self.final_size}, '
                f'resize_range={self.resize_range}, '
                f'crop_x_range={self.crop_x_range}, '
                f'crop_y_range={self.crop_y_range}, '
                f'flip_prob={self.flip_prob}, rot_range={self.rot_range}, '
                f'test_mode={self.test_mode})')
