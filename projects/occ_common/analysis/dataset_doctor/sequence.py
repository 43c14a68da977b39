"""Sequence: files present, time running forward, the car moving plausibly.

Per sample:

* the key frame, every sweep and the previous key frame's LiDAR file and
  images exist (a missing one is a failure naming it);
* ``sweeps``: how many the info lists; ``max_sweep_gap_s``: the longest
  time between the key frame and its newest sweep or between two sweeps
  (nuScenes: 0.05 s); the sweeps' times must fall, newest first, before
  the key frame's;
* ``sweep_pose_error_m`` / ``sweep_pose_error_deg``: each sweep's
  ``sensor2lidar`` against the one its and the key frame's poses give
  (``inv(ego2global_key @ lidar2ego_key) @ ego2global_sweep @
  lidar2ego_sweep``): a sweep merged with wrong poses smears every object;
* ``speed_mps`` / ``yaw_rate_dps``: the ego's motion from the previous key
  frame (or, in a scene's first sample, over its sweeps), where the poses
  of a real car cannot jump;
* ``camera_lag_s``: the largest time between the key frame and one of its
  images.
"""
import os.path as osp
from typing import Optional

import numpy as np

from ...datasets.info_format import as_matrix
from .calibration import transform_difference
from .sample_data import SampleData, prefixed
from .verdict import CheckResult

#: The longest gap between sweeps before a warning (nuScenes: 0.05 s).
WARN_GAP_S = 0.25
#: Sweep poses further than these from the key frame's: fail.
FAIL_POSE_M, FAIL_POSE_DEG = 0.1, 0.5
#: Ego speed (m/s) and yaw rate (degrees/s) above these: warn, fail. A
#: car on a road stays below 40 m/s and turns at under 60 deg/s.
WARN_SPEED, FAIL_SPEED = 40.0, 70.0
WARN_YAW_RATE, FAIL_YAW_RATE = 60.0, 180.0
#: An image further from its key frame than this: warn (nuScenes' cameras
#: fire within 0.05 s of the LiDAR passing them).
WARN_CAMERA_LAG_S = 0.1


def motion(first: np.ndarray, second: np.ndarray, seconds: float) -> tuple:
    """Speed (m/s) and yaw rate (deg/s) between two ego poses.

    Args:
        first (np.ndarray): Ego to global at the earlier time. Shape (4, 4).
        second (np.ndarray): At the later time. Shape (4, 4).
        seconds (float): The time between, > 0.

    Returns:
        tuple[float, float]: Speed and yaw rate.
    """
    distance = np.linalg.norm(second[:3, 3] - first[:3, 3])
    yaw = np.arctan2(second[1, 0], second[0, 0]) - np.arctan2(
        first[1, 0], first[0, 0])
    yaw = (yaw + np.pi) % (2 * np.pi) - np.pi
    return float(distance / seconds), float(np.degrees(abs(yaw)) / seconds)


def _judge_motion(result: CheckResult, speed: float, yaw_rate: float,
                  between: str) -> None:
    result.numbers['speed_mps'] = speed
    result.numbers['yaw_rate_dps'] = yaw_rate
    result.judge(speed, f'the ego moves at {{value:.1f}} m/s {between} '
                 '(poses of another scene, or timestamps in other units?)',
                 lambda v: v > FAIL_SPEED, lambda v: v > WARN_SPEED)
    result.judge(yaw_rate, f'the ego turns at {{value:.0f}} deg/s {between}',
                 lambda v: v > FAIL_YAW_RATE, lambda v: v > WARN_YAW_RATE)


def _check_sweeps(result: CheckResult, sample: SampleData) -> Optional[tuple]:
    """Sweep files, times and poses; returns the oldest sweep's ``(pose,
    time)`` for the motion check."""
    info = sample.info
    key_time = float(info['timestamp'])
    key_to_global = sample.ego2global @ sample.lidar2ego
    previous, gap, pose_m, pose_deg, oldest = key_time, 0.0, 0.0, 0.0, None
    sweeps = info.get('lidar_sweeps') or []
    result.numbers['sweeps'] = float(len(sweeps))
    for index, sweep in enumerate(sweeps):
        where = f'sweep {index} of sample {sample.token}'
        path = sweep['lidar_points']['lidar_path']
        if not osp.isfile(path):
            result.fail(f'{where}: file missing: {path}')
        time = float(sweep['timestamp'])
        if time >= previous:
            result.fail(f'{where} is at {time:.3f} s, not before '
                        f'{previous:.3f} s (the key frame or the newer '
                        'sweep): sweeps must go back in time, newest first')
        gap = max(gap, previous - time)
        previous = time
        pts = sweep['lidar_points']
        if 'ego2global' in sweep and 'lidar2ego' in pts:
            sweep_ego = as_matrix(sweep['ego2global'], [(4, 4)], where)
            sensor_to_global = sweep_ego @ as_matrix(
                pts['lidar2ego'], [(4, 4)], where)
            expected = np.linalg.inv(key_to_global) @ sensor_to_global
            given = pts['sensor2lidar'] if 'sensor2lidar' in pts else \
                np.linalg.inv(pts['lidar2sensor'])
            deg, metres = transform_difference(np.asarray(given), expected)
            pose_m, pose_deg = max(pose_m, metres), max(pose_deg, deg)
            oldest = (sweep_ego, time)
    if sweeps:
        result.numbers['max_sweep_gap_s'] = gap
        result.judge(gap, '{value:.2f} s between two sweeps (sweeps '
                     'missing?)', lambda v: False,
                     lambda v: v > WARN_GAP_S)
    if oldest is not None:
        result.numbers['sweep_pose_error_m'] = pose_m
        result.numbers['sweep_pose_error_deg'] = pose_deg
        if pose_m > FAIL_POSE_M or pose_deg > FAIL_POSE_DEG:
            result.fail(f'a sweep\'s sensor2lidar is {pose_m:.2f} m and '
                        f'{pose_deg:.2f} deg off the one its ego pose and the'
                        ' key frame\'s give: sweeps would be merged with the '
                        'wrong poses')
    return oldest


def _check_previous(result: CheckResult, sample: SampleData,
                    dataset) -> Optional[tuple]:
    """The previous key frame's files and time; returns its ``(pose,
    time)``."""
    link = sample.info.get('prev_key_frame')
    if not link:
        return None
    where = f'previous key frame {link["token"]} of sample {sample.token}'
    files = [prefixed(dataset, 'pts', link['lidar_points']['lidar_path'])]
    files += [prefixed(dataset, 'img', image['img_path'])
              for image in link['images'].values()]
    for path in files:
        if not osp.isfile(path):
            result.fail(f'{where}: file missing: {path}')
    time = link.get('timestamp')
    if time is None:
        return None
    if float(time) >= float(sample.info['timestamp']):
        result.fail(f'{where} is at {float(time):.3f} s, not before the '
                    f'sample ({float(sample.info["timestamp"]):.3f} s)')
        return None
    return as_matrix(link['ego2global'], [(4, 4)], where), float(time)


def check_sequence(sample: SampleData, dataset) -> CheckResult:
    """The ``sequence`` check of one sample (see the module doc).

    Args:
        sample (SampleData): The sample.
        dataset (NuScenesOccDataset): Its dataset (the folders that the
            previous key frame's relative paths are joined to).

    Returns:
        CheckResult: The numbers of the module doc.
    """
    result = CheckResult('sequence')
    for sentence in sample.problems.get('sequence', []):
        result.fail(sentence)
    oldest = _check_sweeps(result, sample)
    previous = _check_previous(result, sample, dataset)
    reference, between = None, ''
    if previous is not None:
        reference, between = previous, 'since the previous key frame'
    elif oldest is not None:
        reference, between = oldest, 'over the sweeps'
    now = float(sample.info['timestamp'])
    if reference is not None and now > reference[1]:
        _judge_motion(result, *motion(reference[0], sample.ego2global,
                                      now - reference[1]), between)
    lags = [abs(float(camera.timestamp) - now) for camera in sample.cameras
            if camera.timestamp is not None]
    if lags:
        result.numbers['camera_lag_s'] = max(lags)
        result.judge(max(lags), 'an image is {value:.2f} s away from its key '
                     'frame (an image of another frame?)', lambda v: False,
                     lambda v: v > WARN_CAMERA_LAG_S)
    return result
