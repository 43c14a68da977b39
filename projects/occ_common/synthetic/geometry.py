"""Rigid transforms and quaternions in nuScenes' conventions.

nuScenes stores rotations as unit quaternions ``[w, x, y, z]`` and every pose
as "sensor -> parent": a ``calibrated_sensor`` record maps sensor coordinates
into the ego frame, an ``ego_pose`` record maps ego coordinates into the
global frame. The helpers here build and apply such 4x4 transforms.
"""
from typing import Sequence

import numpy as np


def rot_z(yaw: float) -> np.ndarray:
    """Rotation about +z by ``yaw`` radians (counter-clockwise seen from
    above).

    Args:
        yaw (float): Angle in radians.

    Returns:
        np.ndarray: Rotation matrix. Shape (3, 3).
    """
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_x(angle: float) -> np.ndarray:
    """Rotation about +x by ``angle`` radians.

    Args:
        angle (float): Angle in radians.

    Returns:
        np.ndarray: Rotation matrix. Shape (3, 3).
    """
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> np.ndarray:
    """Rotation about +y by ``angle`` radians.

    Args:
        angle (float): Angle in radians.

    Returns:
        np.ndarray: Rotation matrix. Shape (3, 3).
    """
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def yaw_quaternion(yaw: float) -> np.ndarray:
    """Quaternion ``[w, x, y, z]`` of a rotation about +z.

    Args:
        yaw (float): Angle in radians.

    Returns:
        np.ndarray: Unit quaternion. Shape (4,).
    """
    return np.array([np.cos(yaw / 2.0), 0.0, 0.0, np.sin(yaw / 2.0)])


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion ``[w, x, y, z]`` of a rotation matrix, with w >= 0.

    Picks the numerically largest of the four diagonal combinations as the
    pivot (Shepperd's method), so matrices near 180 degree rotations (e.g.
    CAM_BACK's) stay accurate.

    Args:
        rotation (np.ndarray): Proper rotation matrix. Shape (3, 3).

    Returns:
        np.ndarray: Unit quaternion. Shape (4,).
    """
    m = np.asarray(rotation, dtype=np.float64)
    trace = np.trace(m)
    pivots = [trace, m[0, 0], m[1, 1], m[2, 2]]
    k = int(np.argmax(pivots))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s,
             (m[1, 0] - m[0, 1]) / s]
    elif k == 1:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s,
             (m[0, 2] + m[2, 0]) / s]
    elif k == 2:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s,
             (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s,
             (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def quaternion_to_matrix(quaternion: Sequence[float]) -> np.ndarray:
    """Rotation matrix of a quaternion ``[w, x, y, z]`` (normalised first).

    Args:
        quaternion (Sequence[float]): Quaternion. Shape (4,).

    Returns:
        np.ndarray: Rotation matrix. Shape (3, 3).
    """
    w, x, y, z = np.asarray(quaternion, dtype=np.float64) / np.linalg.norm(
        quaternion)
    return np.array(
        [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def make_transform(rotation: np.ndarray,
                   translation: Sequence[float]) -> np.ndarray:
    """Homogeneous transform ``[R t; 0 1]``.

    Args:
        rotation (np.ndarray): Rotation matrix. Shape (3, 3).
        translation (Sequence[float]): Translation. Shape (3,).

    Returns:
        np.ndarray: Transform. Shape (4, 4).
    """
    transform = np.eye(4)
    transform[:3, :3] = rotation
    transform[:3, 3] = translation
    return transform


def invert_transform(transform: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform, using ``R^T`` instead of a general
    inverse.

    Args:
        transform (np.ndarray): Rigid transform. Shape (4, 4).

    Returns:
        np.ndarray: Inverse transform. Shape (4, 4).
    """
    rotation = transform[:3, :3].T
    return make_transform(rotation, -rotation @ transform[:3, 3])


def apply_transform(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Applies a 4x4 transform to 3D points.

    Args:
        transform (np.ndarray): Transform. Shape (4, 4).
        points (np.ndarray): Points. Shape (N, 3).

    Returns:
        np.ndarray: Transformed points. Shape (N, 3).
    """
    return points @ transform[:3, :3].T + transform[:3, 3]
