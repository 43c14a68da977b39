"""Photometric distortion of multi-view images, each view on its own.

The distortion of mmdet's ``PhotoMetricDistortion`` (the one that
BEVFormer's and SurroundOcc's ``PhotoMetricDistortionMultiViewImage``
apply per view): brightness, contrast, then saturation and hue in HSV,
each with probability ``prob``, with the same default ranges. Two of their
parts are left out:

- the random order of contrast (first or last): contrast multiplies every
  channel, which scales HSV's V and leaves H and S, so it commutes with
  the colour steps and the order changes nothing;
- the random permutation of the colour channels, which is not a change of
  light: it repaints the classes (green vegetation turns blue) and with
  them the colour cues the image branch has to learn, e.g. brick-red
  other flat ground against terrain in the synthetic world.
"""
from typing import Sequence

import cv2
import numpy as np
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS

#: The parameters of a view that is left as it is.
IDENTITY = dict(brightness=0.0, contrast=1.0, saturation=1.0, hue=0.0)


def distort_view(img: np.ndarray, params: dict) -> np.ndarray:
    """Apply one view's photometric parameters.

    Args:
        img (np.ndarray): A 3-channel view, uint8 or float in 0-255.
            Shape (H, W, 3).
        params (dict): ``brightness`` (added), ``contrast`` (multiplied),
            ``saturation`` (multiplies HSV's S) and ``hue`` (degrees added
            to HSV's H), as from
            :meth:`MultiViewPhotoMetric.sample_params`.

    Returns:
        np.ndarray: The view, clipped to 0-255, in ``img``'s dtype (uint8
        rounded). Shape (H, W, 3).
    """
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError('MultiViewPhotoMetric needs 3-channel views, got '
                         f'shape {img.shape}')
    out = img.astype(np.float32) + np.float32(params['brightness'])
    out = np.clip(out * np.float32(params['contrast']), 0, None)
    if params['saturation'] != 1.0 or params['hue'] != 0.0:
        # OpenCV's float HSV: H in degrees [0, 360), S in [0, 1], V = the
        # largest channel, any scale. The channel order only mirrors the
        # hue's direction, and the hue range is symmetric.
        hsv = cv2.cvtColor(out, cv2.COLOR_BGR2HSV)
        hsv[..., 1] = np.clip(hsv[..., 1] * params['saturation'], 0, 1)
        hsv[..., 0] = (hsv[..., 0] + params['hue']) % 360
        out = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)
    out = np.clip(out, 0, 255)
    if img.dtype == np.uint8:
        return np.round(out).astype(np.uint8)
    return out.astype(img.dtype)


@TRANSFORMS.register_module()
class MultiViewPhotoMetric(BaseTransform):
    """Random brightness, contrast, saturation and hue per camera view.

    Every view draws its own parameters, as each camera of a rig has its
    own exposure and white balance: with probability ``prob`` each,
    brightness ``+U(-brightness_delta, brightness_delta)``, contrast
    ``x U(contrast_range)``, saturation ``x U(saturation_range)`` and hue
    ``+U(-hue_delta, hue_delta)`` degrees. Geometry is untouched, so it
    can sit anywhere after the images are loaded; after
    :class:`MultiViewImageAug` it works on the small images. Training
    only: a test pipeline leaves it out.

    Args:
        brightness_delta (float): Defaults to 32 (mmdet's).
        contrast_range (Sequence[float]): Defaults to (0.5, 1.5).
        saturation_range (Sequence[float]): Defaults to (0.5, 1.5).
        hue_delta (float): Degrees. Defaults to 18.
        prob (float): Probability of each of the four steps.
            Defaults to 0.5.

    Required Keys:

    - img (list[np.ndarray]): N views, each (H, W, 3), uint8 or float in
      0-255.

    Modified Keys:

    - img: the distorted views, same shapes and dtypes.

    Added Keys:

    - img_photometric_params (list[dict]): Per view, the parameters of
      :func:`distort_view`.
    """

    def __init__(self,
                 brightness_delta: float = 32.0,
                 contrast_range: Sequence[float] = (0.5, 1.5),
                 saturation_range: Sequence[float] = (0.5, 1.5),
                 hue_delta: float = 18.0,
                 prob: float = 0.5) -> None:
        for name, rng in (('contrast_range', contrast_range),
                          ('saturation_range', saturation_range)):
            if len(rng) != 2 or not 0 <= rng[0] <= rng[1]:
                raise ValueError(f'MultiViewPhotoMetric: {name} must be '
                                 f'(low, high) with 0 <= low <= high, got '
                                 f'{rng}')
        if brightness_delta < 0 or not 0 <= hue_delta <= 180:
            raise ValueError('MultiViewPhotoMetric: brightness_delta must '
                             'be >= 0 and hue_delta in [0, 180], got '
                             f'{brightness_delta} and {hue_delta}')
        if not 0 <= prob <= 1:
            raise ValueError(f'MultiViewPhotoMetric: prob must be in [0, '
                             f'1], got {prob}')
        self.brightness_delta = float(brightness_delta)
        self.contrast_range = tuple(float(v) for v in contrast_range)
        self.saturation_range = tuple(float(v) for v in saturation_range)
        self.hue_delta = float(hue_delta)
        self.prob = float(prob)

    def _maybe(self, low: float, high: float, default: float) -> float:
        if np.random.rand() < self.prob:
            return float(np.random.uniform(low, high))
        return default

    def sample_params(self) -> dict:
        """Draw the distortion of one view.

        Returns:
            dict: The keys of :data:`IDENTITY`.
        """
        delta, hue = self.brightness_delta, self.hue_delta
        return dict(
            brightness=self._maybe(-delta, delta, 0.0),
            contrast=self._maybe(*self.contrast_range, 1.0),
            saturation=self._maybe(*self.saturation_range, 1.0),
            hue=self._maybe(-hue, hue, 0.0))

    def transform(self, results: dict) -> dict:
        """Distort every view of one sample.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The state with distorted views.
        """
        params = [self.sample_params() for _ in results['img']]
        results['img'] = [
            distort_view(img, p) for img, p in zip(results['img'], params)
        ]
        results['img_photometric_params'] = params
        return results
