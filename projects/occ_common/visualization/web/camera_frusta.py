"""Camera frusta in the grid's frame, from the projection the pipeline
packs.

``lidar2img`` (``img_aug_matrix @ cam2img @ lidar2cam``, 4 x 4 with the
intrinsics padded) maps a point of the working frame to ``(u d, v d, d,
1)``: pixel ``(u, v)`` at depth ``d``. Its inverse maps such a tuple back,
so the camera centre is the inverse applied to ``(0, 0, 0, 1)`` and the
corner of pixel ``(u, v)`` at depth ``d`` the inverse applied to
``(u d, v d, d, 1)``; an augmented image (resized, cropped, flipped) gets
the frustum of what it shows.
"""
from typing import Sequence

import numpy as np


def frustum_corners(lidar2img: np.ndarray, image_hw: Sequence[int],
                    depth: float) -> np.ndarray:
    """The centre and the image corners of every camera at ``depth``.

    Args:
        lidar2img (np.ndarray): Working frame to pixels. Shape (N, 4, 4).
        image_hw (Sequence[int]): ``(H, W)`` of the images.
        depth (float): Depth of the corners, metres along the optical axis.

    Returns:
        np.ndarray: Per camera the centre, then the corners of pixels
        ``(0, 0)``, ``(W, 0)``, ``(W, H)``, ``(0, H)`` (top left, top
        right, bottom right, bottom left of the image). Shape (N, 5, 3).

    Raises:
        ValueError: If ``lidar2img`` is not (N, 4, 4), is singular, or its
            last row is not ``(0, 0, 0, 1)``, or ``depth`` is not positive.
    """
    matrices = np.asarray(lidar2img, dtype=np.float64)
    if matrices.ndim != 3 or matrices.shape[1:] != (4, 4):
        raise ValueError('frustum_corners: expected lidar2img of shape '
                         f'(N, 4, 4), got {matrices.shape}.')
    if not depth > 0:
        raise ValueError(f'frustum_corners: depth must be positive, got '
                         f'{depth}.')
    if not np.allclose(matrices[:, 3], [0, 0, 0, 1], atol=1e-6):
        raise ValueError('frustum_corners: lidar2img must be intrinsics '
                         'padded to 4 x 4 (last row 0, 0, 0, 1), got last '
                         f'rows {matrices[:, 3].tolist()}.')
    height, width = (float(v) for v in image_hw)
    pixels = np.array([[0, 0], [width, 0], [width, height], [0, height]])
    targets = np.zeros((5, 4))
    targets[:, 3] = 1
    targets[1:, :2] = pixels * depth
    targets[1:, 2] = depth
    try:
        inverse = np.linalg.inv(matrices)
    except np.linalg.LinAlgError:
        raise ValueError('frustum_corners: a lidar2img matrix is '
                         'singular.') from None
    points = np.einsum('nij,kj->nki', inverse, targets)
    return points[..., :3] / points[..., 3:]
