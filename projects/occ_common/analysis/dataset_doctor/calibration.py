"""Calibration: do the cameras' matrices fit their images and the LiDAR?

Per camera of a sample (numbers keyed ``<camera>.<name>``):

* ``width_ratio`` / ``height_ratio``: the image's size over the size its
  calibration was recorded for (1: the image was not resized after
  calibration; the converter records it);
* ``principal_x`` / ``principal_y``: the principal point as a share of the
  image's width / height, near 0.5 for every nuScenes-like camera (an
  intrinsic matrix of another image size puts it elsewhere);
* ``focal_aspect``: ``fx / fy``, near 1 for square pixels;
* ``orthonormality``: the largest entry of ``R^T R - I`` of the
  ``lidar2cam`` and ``cam2ego`` rotations (a transposed or scaled matrix
  is still caught where ``R^T R = I`` holds by the next number);
* ``extrinsic_deg`` / ``extrinsic_m``: ``lidar2cam`` against the one the
  sensors' mounts give, ``inv(cam2ego) @ lidar2ego``: the angle and the
  distance between them. nuScenes goes through the global frame with each
  sensor's capture time, so they differ by the car's motion in the few
  milliseconds between (a few centimetres); a transposed, inverted or
  swapped extrinsic differs by tens of degrees;
* ``down_z``: the ego-frame height component of the camera's down axis,
  about -1 for an upright camera;
* ``lidar2img_error``: where the info stores its own ``lidar2img``, its
  largest difference from ``cam2img @ lidar2cam`` relative to the largest
  entry (a matrix left stale when the calibration was edited);
* ``points_in_view``: key-frame points projected inside the image in
  front of the camera; ``median_depth``: their median depth (metres: a
  LiDAR in millimetres or centimetres shows here);
* ``edge_alignment`` / ``edge_points``: :mod:`.edge_alignment`'s score,
  where the image was read (a weak signal on one frame: it only warns,
  and only over :data:`ALIGNMENT_POINTS` reflectivity edges);

and per pair of cameras that see at least
:data:`~.edge_alignment.MIN_SHARED_POINTS` points in common
(``<camera>|<camera>.overlap_consistency`` and ``.overlap_points``):
whether the two images agree at the shared points, the check that tells
a swapped camera or an extrinsic looking the wrong way.

The thresholds are module constants; the measured values of the synthetic
world and of the real nuScenes key frame beside the checkout are in
``docs/customize_dataset.md``.
"""
import numpy as np

from .edge_alignment import edge_alignment, overlap_consistency
from .sample_data import CameraData, SampleData
from .verdict import CheckResult

#: A recorded and an actual image size differ by more than this share.
SIZE_TOLERANCE = 0.01
#: The principal point outside this share of the image: another image's.
PRINCIPAL_RANGE = (0.25, 0.75)
#: ``fx / fy`` further than this from 1: warn (non-square pixels, or one
#: axis rescaled).
ASPECT_TOLERANCE = 0.05
#: ``R^T R - I`` entries above this: not a rotation.
ORTHONORMAL_TOLERANCE = 1e-3
#: ``lidar2cam`` against the mounts: warn / fail above these angles
#: (degrees) and distances (metres).
WARN_DEG, FAIL_DEG = 1.0, 5.0
WARN_M, FAIL_M = 0.5, 2.0
#: The camera's down axis pointing less down than this: warn (a camera
#: mounted upside down or on its side, or a rotation of the wrong frame).
UPRIGHT_Z = -0.5
#: Nearest depth (m) of a point counted as in front of the camera.
MIN_DEPTH = 0.5
#: Median depth (m) of the points in view above these: warn, fail (a
#: driving scene's points lie within 1-60 m; beyond 200 m the LiDAR's
#: unit is not the metre).
WARN_DEPTH, FAIL_DEPTH = 80.0, 200.0
#: A stored lidar2img this far (relative) from cam2img @ lidar2cam: warn.
STALE_TOLERANCE = 1e-3
#: Edge alignment below this, over at least ``ALIGNMENT_POINTS`` edge
#: points: warn. The real nuScenes key frame beside the checkout scores
#: 1.14 to 1.65 on its six cameras (68 to 247 edge points), on another
#: camera's image 0.59 to 1.15; the synthetic world's flat-shaded classes
#: give few reflectivity edges (measured 2026-11).
WARN_ALIGNMENT, ALIGNMENT_POINTS = 1.05, 100
#: Overlap consistency below these: fail, warn. Measured: 0.71 to 0.96 on
#: the real key frame's five overlapping pairs and 0.68 to 0.98 on the
#: synthetic world's; -0.78 to 0.39 where two cameras' images are swapped
#: (the real frame's CAM_FRONT and CAM_BACK: -0.69, -0.34, -0.34; 2026-11).
FAIL_OVERLAP, WARN_OVERLAP = 0.4, 0.5


def rotation_error(matrix: np.ndarray) -> float:
    """Largest entry of ``|R^T R - I|``, or inf for a reflection."""
    rot = np.asarray(matrix, np.float64)[:3, :3]
    if np.linalg.det(rot) <= 0:
        return float('inf')
    return float(np.abs(rot.T @ rot - np.eye(3)).max())


def transform_difference(first: np.ndarray, second: np.ndarray) -> tuple:
    """Angle (degrees) and distance (metres) between two 4x4 transforms:
    of the rotation ``R1 R2^T`` and of the translations."""
    rot = first[:3, :3] @ second[:3, :3].T
    cos = np.clip((np.trace(rot) - 1) / 2, -1.0, 1.0)
    return (float(np.degrees(np.arccos(cos))),
            float(np.linalg.norm(first[:3, 3] - second[:3, 3])))


def _check_camera(result: CheckResult, camera: CameraData,
                  sample: SampleData) -> None:
    name = camera.name
    numbers = result.numbers
    height, width = camera.image.shape[:2] if camera.image is not None \
        else (camera.recorded_size or (None, None))
    if camera.image is not None and camera.recorded_size is not None:
        rec_h, rec_w = camera.recorded_size
        numbers[f'{name}.width_ratio'] = width / rec_w
        numbers[f'{name}.height_ratio'] = height / rec_h
        if max(abs(width / rec_w - 1), abs(height / rec_h - 1)) > \
                SIZE_TOLERANCE:
            result.fail(f'{name}: the image is {width}x{height} but its '
                        f'calibration is for {rec_w}x{rec_h} (resized '
                        f'after calibration?): {camera.img_path}')
    k = camera.cam2img
    if width is not None:
        px, py = k[0, 2] / width, k[1, 2] / height
        numbers[f'{name}.principal_x'] = px
        numbers[f'{name}.principal_y'] = py
        low, high = PRINCIPAL_RANGE
        if not (low <= px <= high and low <= py <= high):
            result.fail(f'{name}: the principal point ({k[0, 2]:.1f}, '
                        f'{k[1, 2]:.1f}) is not in the middle of the '
                        f'{width}x{height} image: cam2img belongs to '
                        'another image size')
    aspect = k[0, 0] / k[1, 1] if k[1, 1] else float('inf')
    numbers[f'{name}.focal_aspect'] = aspect
    result.judge(aspect, f'{name}: fx / fy is {{value:.3f}}, not 1 (one '
                 'axis of the image rescaled?)', lambda v: not v > 0,
                 lambda v: abs(v - 1) > ASPECT_TOLERANCE)
    error = max(rotation_error(camera.lidar2cam),
                rotation_error(camera.cam2ego))
    numbers[f'{name}.orthonormality'] = error
    result.judge(error, f'{name}: lidar2cam or cam2ego is no rotation '
                 '(|R^T R - I| up to {value:.2g}, or a reflection)',
                 lambda v: v > ORTHONORMAL_TOLERANCE)
    mounts = np.linalg.inv(camera.cam2ego) @ sample.lidar2ego
    deg, metres = transform_difference(camera.lidar2cam, mounts)
    numbers[f'{name}.extrinsic_deg'] = deg
    numbers[f'{name}.extrinsic_m'] = metres
    if deg > FAIL_DEG or metres > FAIL_M:
        result.fail(f'{name}: lidar2cam is {deg:.1f} deg and {metres:.2f} '
                    'm off the one cam2ego and lidar2ego give (transposed, '
                    'inverted or another camera\'s extrinsic?)')
    elif deg > WARN_DEG or metres > WARN_M:
        result.warn(f'{name}: lidar2cam is {deg:.1f} deg and {metres:.2f} '
                    'm off the one cam2ego and lidar2ego give')
    if camera.recorded_lidar2img is not None:
        scale = max(np.abs(camera.lidar2img).max(), 1e-12)
        stale = float(np.abs(camera.recorded_lidar2img -
                             camera.lidar2img).max() / scale)
        numbers[f'{name}.lidar2img_error'] = stale
        result.judge(stale, f'{name}: the info\'s lidar2img differs from '
                     'cam2img @ lidar2cam by {value:.2g} of its largest '
                     'entry (left stale when the calibration changed?)',
                     lambda v: False, lambda v: v > STALE_TOLERANCE)
    down_z = float(camera.cam2ego[2, 1])
    numbers[f'{name}.down_z'] = down_z
    result.judge(down_z, f'{name}: the camera\'s down axis points '
                 '{value:+.2f} up in the ego frame (mounted on its side or '
                 'upside down, or cam2ego of another frame)',
                 lambda v: False, lambda v: v > UPRIGHT_Z)
    _check_projection(result, camera, sample, width, height)


def _check_projection(result: CheckResult, camera: CameraData,
                      sample: SampleData, width, height) -> None:
    """``points_in_view`` and, with an image, ``edge_alignment``."""
    if width is None or not len(sample.points):
        return
    u, v, inside, depth = in_view(sample.points, camera, width, height)
    count = int(inside.sum())
    result.numbers[f'{camera.name}.points_in_view'] = float(count)
    if count == 0:
        result.fail(f'{camera.name}: no LiDAR point projects into the '
                    'image (the extrinsic looks away from the scene)')
        return
    median = float(np.median(depth[inside]))
    result.numbers[f'{camera.name}.median_depth'] = median
    result.judge(median, f'{camera.name}: the points in view lie {{value:.0f}}'
                 ' m away on the median (a LiDAR in another unit than the '
                 'metre?)', lambda v: v > FAIL_DEPTH,
                 lambda v: v > WARN_DEPTH)
    if camera.image is None or sample.points.shape[1] < 4:
        return
    score = edge_alignment(camera.image, u[inside], v[inside],
                           sample.points[inside, 3])
    for key, value in score.items():
        result.numbers[f'{camera.name}.{key}'] = value
    if score['edge_points'] >= ALIGNMENT_POINTS:
        result.judge(score['edge_alignment'], f'{camera.name}: the LiDAR\'s'
                     ' reflectivity edges land on image edges {value:.2f}x '
                     'as often as by chance', lambda v: False,
                     lambda v: v < WARN_ALIGNMENT)


def in_view(points: np.ndarray, camera: CameraData, width: int,
            height: int) -> tuple:
    """Pixels of every point and which of them the camera sees.

    Returns:
        tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ``u``,
        ``v`` (Shape (P,), NaN behind the camera), ``inside`` (bool,
        Shape (P,): in front, within the image) and the depth.
    """
    mat = camera.lidar2img
    cam = points[:, :3].astype(np.float64) @ mat[:3, :3].T + mat[:3, 3]
    front = cam[:, 2] >= MIN_DEPTH
    depth = np.where(front, cam[:, 2], np.nan)
    u, v = cam[:, 0] / depth, cam[:, 1] / depth
    with np.errstate(invalid='ignore'):
        inside = front & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    return u, v, inside, depth


def unoccluded(u: np.ndarray, v: np.ndarray, depth: np.ndarray,
               inside: np.ndarray, width: int) -> np.ndarray:
    """Which points in view are the nearest in their patch of the image.

    The LiDAR, mounted above and behind the cameras, sees surfaces a camera
    does not (behind a car's roof, round a corner); such a point projects
    onto the occluder in the image. A point counts as visible where it is
    within 0.3 m and 10 % of the nearest point in its cell of
    ``max(4, width / 40)`` pixels (a cell a few LiDAR points wide on
    nuScenes' 1600x900 images and on 160x90 ones, so that an occluder's
    own points fall in the cells of the points it hides).

    Returns:
        np.ndarray: bool, a subset of ``inside``. Shape (P,).
    """
    cell = max(4.0, width / 40)
    cols = np.floor(np.where(inside, u, 0) / cell).astype(np.int64)
    rows = np.floor(np.where(inside, v, 0) / cell).astype(np.int64)
    key = rows * (int(width / cell) + 2) + cols
    nearest = np.full(int(key.max()) + 1 if len(key) else 0, np.inf)
    np.minimum.at(nearest, key[inside], depth[inside])
    limit = nearest[key] * 1.1 + 0.3
    return inside & (np.where(inside, depth, np.inf) <= limit)


def _check_overlaps(result: CheckResult, sample: SampleData) -> None:
    """``overlap_consistency`` of every pair of cameras with images."""
    cameras = [c for c in sample.cameras if c.image is not None]
    views = []
    for camera in cameras:
        u, v, inside, depth = in_view(sample.points, camera,
                                      camera.image.shape[1],
                                      camera.image.shape[0])
        views.append((u, v, unoccluded(u, v, depth, inside,
                                       camera.image.shape[1])))
    for i, first in enumerate(cameras):
        for j in range(i + 1, len(cameras)):
            second = cameras[j]
            shared = views[i][2] & views[j][2]
            if not shared.any():
                continue
            score = overlap_consistency(
                first.image, second.image,
                (views[i][0][shared], views[i][1][shared]),
                (views[j][0][shared], views[j][1][shared]))
            pair = f'{first.name}|{second.name}'
            for key, value in score.items():
                result.numbers[f'{pair}.{key}'] = value
            result.judge(score['overlap_consistency'], f'{pair}: the two '
                         'images disagree where they see the same LiDAR '
                         'points (rank correlation {value:.2f}; swapped '
                         'cameras, or an extrinsic looking the wrong way?)',
                         lambda v: v < FAIL_OVERLAP,
                         lambda v: v < WARN_OVERLAP)


def check_calibration(sample: SampleData) -> CheckResult:
    """The ``calibration`` check of one sample (see the module doc).

    Args:
        sample (SampleData): The sample.

    Returns:
        CheckResult: Numbers per camera, plus ``lidar2ego.orthonormality``
        and ``ego2global.orthonormality``.
    """
    result = CheckResult('calibration')
    for sentence in sample.problems.get('calibration', []):
        result.fail(sentence)
    for key, matrix in (('lidar2ego', sample.lidar2ego),
                        ('ego2global', sample.ego2global)):
        error = rotation_error(matrix)
        result.numbers[f'{key}.orthonormality'] = error
        result.judge(error, f'{key} is no rotation (|R^T R - I| up to '
                     '{value:.2g}, or a reflection)',
                     lambda v: v > ORTHONORMAL_TOLERANCE)
    if not sample.cameras:
        result.skipped = 'no cameras'
        return result
    for camera in sample.cameras:
        _check_camera(result, camera, sample)
    if len(sample.points):
        _check_overlaps(result, sample)
    return result
