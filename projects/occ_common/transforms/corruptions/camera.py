"""Camera failures of a loaded sample: every view's pixels, crashed,
blacked-out, stale and missing views.

Each function changes the pipeline state of one sample in place, as
``LoadMultiViewImagesOcc`` left it: ``img`` a list of N uint8 views Shape
(H, W, 3) and the per-view matrices (N, 4, 4). What "absent" means
differs on purpose:

* a *crashed* or *blacked-out* view is a black image whose calibration is
  still there (the camera is known, its stream delivers zeros: RoboBEV's
  camera crash);
* a *missing* view is gone: its image and every per-view entry are
  dropped, and the model sees N - k views (the camera is unplugged; the
  detectors take any number of views, see the robustness docs).
"""
from typing import Callable

import numpy as np

from ..image_loading import LoadMultiViewImagesOcc

#: Per-view entries of the pipeline state that a missing view takes with it
#: (lists or arrays whose first axis is the view), where present.
PER_VIEW_KEYS = ('img', 'img_path', 'cam_names', 'cam2img', 'lidar2cam',
                 'cam2ego', 'img_aug_matrix', 'lidar2img', 'img_aug_params',
                 'gt_depth', 'gt_seg_2d')


def _views(results: dict) -> list:
    """The loaded views, checked to be uint8 (H, W, 3)."""
    imgs = results.get('img')
    if imgs is None:
        raise ValueError(
            f'sample {results.get("token", "?")}: OccCorruption needs the '
            'loaded views (results["img"]); place it after '
            'LoadMultiViewImagesOcc')
    for img in imgs:
        if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
            raise ValueError(
                f'sample {results.get("token", "?")}: OccCorruption works '
                'on the loaded uint8 views of shape (H, W, 3), got '
                f'{img.dtype} {img.shape}; place it before any transform '
                'that converts them (LoadMultiViewImagesOcc(to_float32='
                'False), the default)')
    return imgs


def every_view(corrupt: Callable) -> Callable:
    """A condition that applies ``corrupt(view, level, rng)`` (one of
    :mod:`.pixels`) to every view, in view order."""

    def apply(results: dict, level, rng: np.random.Generator) -> None:
        imgs = _views(results)
        # One stream per view: a view's draws do not depend on how many
        # the views before it took at this severity.
        results['img'] = [corrupt(img, level, child)
                          for img, child in zip(imgs, rng.spawn(len(imgs)))]

    apply.__name__ = corrupt.__name__
    apply.__doc__ = corrupt.__doc__
    return apply


def camera_crash(results: dict, count: int,
                 rng: np.random.Generator) -> None:
    """The first ``count`` views of a random order turn black (their
    calibration stays; all of them when ``count`` >= N): those of a lower
    severity among them."""
    imgs = _views(results)
    for i in rng.permutation(len(imgs))[:count]:
        imgs[i] = np.zeros_like(imgs[i])


def camera_blackout(results: dict, prob: float,
                    rng: np.random.Generator) -> None:
    """With probability ``prob`` every view of the sample is black (the
    camera system is down for this frame; calibration stays)."""
    imgs = _views(results)
    if rng.random() < prob:
        results['img'] = [np.zeros_like(img) for img in imgs]


def frame_lost(results: dict, prob: float,
               rng: np.random.Generator) -> None:
    """Each view, with probability ``prob``, shows the previous key
    frame's image of its camera (its driver repeats the last frame it
    has); its calibration is unchanged, so what it shows is stale by one
    key-frame interval (0.5 s in nuScenes).

    Needs ``prev_frames`` (``NuScenesOccDataset(num_frames >= 2)``); the
    first key frame of a scene is its own previous frame, as for the
    temporal models.
    """
    imgs = _views(results)
    lost = np.flatnonzero(rng.random(len(imgs)) < prob)
    if not len(lost):
        return
    frames = results.get('prev_frames')
    token = results.get('token', '?')
    if not frames:
        raise ValueError(
            f'sample {token}: frame_lost shows the previous key frame, '
            'which this sample does not carry (prev_frames); build the '
            'dataset with num_frames=2 (tools/analysis_tools/robustness.py '
            'does)')
    cams = [results['cam_names'][i] for i in lost]
    previous = LoadMultiViewImagesOcc(cam_names=cams)(
        dict(images=frames[0]['images'], token=frames[0]['token']))
    for i, img in zip(lost, previous['img']):
        if img.shape != imgs[i].shape:
            raise ValueError(
                f'sample {token}: the previous key frame\'s '
                f'{results["cam_names"][i]} image is {img.shape}, this '
                f'frame\'s {imgs[i].shape}')
        imgs[i] = img


def missing_views(results: dict, count: int,
                  rng: np.random.Generator) -> None:
    """The first ``count`` views (at most N - 1) of a random order are
    dropped with every per-view entry (:data:`PER_VIEW_KEYS`);
    ``num_views`` follows."""
    num = len(_views(results))
    drop = rng.permutation(num)[:min(count, num - 1)]
    keep = np.setdiff1d(np.arange(num), drop)
    for key in PER_VIEW_KEYS:
        if key not in results:
            continue
        value = results[key]
        if len(value) != num:
            raise ValueError(
                f'sample {results.get("token", "?")}: {key} has '
                f'{len(value)} entries for {num} views')
        results[key] = (value[keep] if isinstance(value, np.ndarray) else
                        [value[i] for i in keep])
    results['num_views'] = len(keep)
