"""Checks of a sample's times and rigid transforms, done once per sample
when :class:`.NuScenesOccDataset` reads its info file.

Each was accepted silently before and gave wrong inputs: a NaN timestamp
(the sweeps' time lags became NaN), a sweep time-stamped after its key
frame (a negative time lag: the "past" scan from the future), an all-zero
``sensor2lidar`` (every sweep point moved to the origin), and a previous
key frame from the future (a temporal model fused the next frame as the
last one). Every message names the info file, the sample and the key.
"""
import math

import numpy as np

#: Largest gap between a key frame and the previous one a temporal sample
#: may use, in seconds. nuScenes' key frames are 0.5 s apart (2 Hz); four
#: intervals allow a few skipped key frames, a larger gap is no sequence.
MAX_FRAME_GAP = 2.0

#: How far ``R^T R`` of a rigid transform may be from the identity
#: (float32 storage keeps it within ~1e-6).
RIGID_TOLERANCE = 1e-3


def check_seconds(value, where: str) -> float:
    """A timestamp in seconds: a finite number.

    Args:
        value: The info file's value.
        where (str): File, sample and key, for the message.

    Returns:
        float: The value.

    Raises:
        ValueError: If it is not a number (a string would fail much later,
            without naming the file) or not finite.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(
            value, (int, float, np.integer, np.floating)):
        raise ValueError(f'{where}: expected a number of seconds, got '
                         f'{type(value).__name__} {value!r:.40}')
    if not math.isfinite(value):
        raise ValueError(f'{where}: expected a finite number of seconds, '
                         f'got {value}')
    return float(value)


def check_rigid(mat: np.ndarray, where: str) -> np.ndarray:
    """A 4x4 rigid transform: a rotation, a translation, ``[0, 0, 0, 1]``.

    Args:
        mat (np.ndarray): Shape (4, 4), finite (``as_matrix``).
        where (str): File, sample and key, for the message.

    Returns:
        np.ndarray: ``mat``.

    Raises:
        ValueError: If its last row is not ``[0, 0, 0, 1]`` or its 3x3
            block is not a rotation (all zeros, a scale, a mirror): it is
            then not the pose or calibration of a sensor, and not
            invertible as one.
    """
    rot = mat[:3, :3]
    if not np.allclose(mat[3], (0, 0, 0, 1), atol=RIGID_TOLERANCE) or \
            not np.allclose(rot.T @ rot, np.eye(3), atol=RIGID_TOLERANCE) \
            or np.linalg.det(rot) < 0:
        raise ValueError(
            f'{where}: expected a rigid transform (a rotation and a '
            f'translation), got {np.round(mat, 4).tolist()}; it would move '
            'every point it maps.')
    return mat


def check_sweep_time(sweep_time: float, key_time: float, where: str) -> None:
    """A sweep is a scan before (or at) its key frame.

    Raises:
        ValueError: If it is time-stamped after the key frame.
    """
    if sweep_time > key_time:
        raise ValueError(
            f'{where}: the sweep is time-stamped {sweep_time - key_time:.3f}'
            f' s after its key frame ({sweep_time} > {key_time}); sweeps are'
            ' the scans before it (their time lag would be negative).')


def check_previous_time(previous: float, later: float, where: str) -> None:
    """A previous key frame lies in the past, within :data:`MAX_FRAME_GAP`.

    Args:
        previous (float): The previous key frame's timestamp (seconds).
        later (float): The frame after it.
        where (str): File, sample and frame, for the message.

    Raises:
        ValueError: If it is not earlier, or more than the gap earlier.
    """
    gap = later - previous
    if not 0 < gap <= MAX_FRAME_GAP:
        raise ValueError(
            f'{where}: the previous key frame is time-stamped {gap:.3f} s '
            f'before the frame after it ({previous} vs {later}); expected '
            f'a frame of the past within {MAX_FRAME_GAP} s (nuScenes key '
            'frames are 0.5 s apart). Re-create the info file with '
            'tools/create_data.py --overwrite.')


__all__ = [
    'MAX_FRAME_GAP', 'RIGID_TOLERANCE', 'check_previous_time',
    'check_rigid', 'check_seconds', 'check_sweep_time'
]
