"""Which way is ahead of the car in a grid: every top-down picture puts it up.

The grids of this library live in the working frame of their label format
(:mod:`projects.occ_common.datasets.occ_formats`): Occ3D's in the ego frame,
whose +x points ahead of the car, SurroundOcc's in the LiDAR frame. nuScenes
mounts ``LIDAR_TOP`` at a yaw of about -90 degrees, so there +y points ahead
and +x to the right of the car. A picture that always put grid +x up would
show SurroundOcc scenes with the road ahead to the left; the renderers take
the grid direction that points ahead (``'+x'``, ``'+y'``, ``'-x'`` or
``'-y'``) instead, found from the sample's ``lidar2ego`` when it has one.
"""
from typing import Optional

import numpy as np

#: The four grid directions a picture can put up, and their heading (degrees
#: counter-clockwise from +x).
FORWARD_HEADINGS = {'+x': 0.0, '+y': 90.0, '-x': 180.0, '-y': -90.0}

#: Grid direction ahead of the car in each label convention's frame when no
#: ``lidar2ego`` tells it: Occ3D's ego frame, SurroundOcc's LiDAR frame.
CONVENTION_FORWARD = {'occ3d': '+x', 'surroundocc': '+y'}


def check_forward(forward: str) -> str:
    """``forward`` if it names a grid direction.

    Raises:
        ValueError: For anything but ``'+x'``, ``'+y'``, ``'-x'``, ``'-y'``.
    """
    if forward not in FORWARD_HEADINGS:
        raise ValueError(f'Expected forward in {sorted(FORWARD_HEADINGS)}, '
                         f'got {forward!r}.')
    return forward


def forward_from_lidar2ego(lidar2ego) -> str:
    """The grid direction nearest to the ego's +x (ahead of the car).

    Args:
        lidar2ego (array-like): Working frame to ego frame. Shape (4, 4)
            or (3, 3).

    Returns:
        str: ``'+x'``, ``'+y'``, ``'-x'`` or ``'-y'``. The identity (Occ3D,
        after ``PointsToEgoFrame``) gives ``'+x'``; nuScenes' LiDAR frame
        (yaw -90 degrees) gives ``'+y'``.

    Raises:
        ValueError: If the matrix is not (3, 3) / (4, 4), or the ego's
            forward axis is (nearly) vertical in the working frame.
    """
    matrix = np.asarray(lidar2ego, dtype=np.float64)
    if matrix.shape not in ((3, 3), (4, 4)):
        raise ValueError('Expected lidar2ego of shape (4, 4) or (3, 3), got '
                         f'{matrix.shape}.')
    # Ego +x expressed in the working frame: the first row of the rotation.
    ahead = matrix[0, :2]
    if np.hypot(*ahead) < 1e-3:
        raise ValueError('lidar2ego: the ego forward axis is vertical in the '
                         f'working frame: {matrix[0, :3].tolist()}.')
    axis = int(np.argmax(np.abs(ahead)))
    return ('+' if ahead[axis] > 0 else '-') + 'xy'[axis]


def sample_forward(lidar2ego=None, convention: Optional[str] = None) -> str:
    """Ahead of the car for a sample: from ``lidar2ego``, else the
    convention's frame, else ``'+x'``.

    Args:
        lidar2ego (array-like, optional): Shape (4, 4). Defaults to None.
        convention (str, optional): ``'surroundocc'`` or ``'occ3d'``.
            Defaults to None.

    Returns:
        str: A key of :data:`FORWARD_HEADINGS`.
    """
    if lidar2ego is not None:
        return forward_from_lidar2ego(lidar2ego)
    return CONVENTION_FORWARD.get(convention, '+x')
