"""Top-down (bird's-eye) class-coloured view of an occupancy grid.

Each (x, y) column becomes one pixel block coloured by the class of its
highest drawn voxel, as a camera looking straight down would see it, with
ahead of the car up and the car's left on the left
(:mod:`.orientation`). With ``forward='+x'`` (the ego frame, Occ3D) image
row ``r`` and column ``c`` show grid column ``(X - 1 - r // scale,
Y - 1 - c // scale)``; with ``forward='+y'`` (nuScenes' LiDAR frame,
SurroundOcc) they show ``(c // scale, Y - 1 - r // scale)``.
"""
from typing import Optional, Sequence

import numpy as np

from .label_grid import occupied_voxels
from .orientation import check_forward
from .palette import BACKGROUND

#: Quarter turns (``np.rot90``) of an (X, Y) array that put each grid
#: direction up the image and the car's left on the left.
_QUARTER_TURNS = {'+x': 2, '+y': 1, '-x': 0, '-y': 3}


def top_labels(labels: np.ndarray, drawn: np.ndarray) -> np.ndarray:
    """Label of the highest drawn voxel of every column.

    Args:
        labels (np.ndarray): Shape (X, Y, Z), int.
        drawn (np.ndarray): Voxels that can be seen, Shape (X, Y, Z), bool.

    Returns:
        np.ndarray: Shape (X, Y), int64; -1 where a column has no drawn
        voxel.
    """
    height = labels.shape[2]
    # argmax finds the first True from the top of the flipped column.
    from_top = np.argmax(drawn[..., ::-1], axis=2)
    top = height - 1 - from_top
    picked = np.take_along_axis(labels, top[..., None], axis=2)[..., 0]
    # int64 before -1 joins: numpy 2 keeps a uint8 array's type and refuses
    # the -1 (NEP 50); numpy 1 widened it.
    return np.where(drawn.any(axis=2), picked.astype(np.int64), -1)


def columns_to_image(columns: np.ndarray,
                     scale: int = 1,
                     forward: str = '+x') -> np.ndarray:
    """Lay an (X, Y, ...) column array out as a BEV image.

    Args:
        columns (np.ndarray): Shape (X, Y) or (X, Y, 3).
        scale (int): Pixels per voxel side. Defaults to 1.
        forward (str): Grid direction ahead of the car, drawn up.
            Defaults to '+x'.

    Returns:
        np.ndarray: Shape (X * scale, Y * scale[, 3]) for ``forward`` along
        x, (Y * scale, X * scale[, 3]) along y.
    """
    if scale < 1:
        raise ValueError(f'Expected scale >= 1, got {scale}.')
    image = np.rot90(columns, _QUARTER_TURNS[check_forward(forward)],
                     axes=(0, 1))
    return np.repeat(np.repeat(image, scale, axis=0), scale, axis=1)


def render_bev(labels: np.ndarray,
               palette: np.ndarray,
               empty_label: int,
               ignore_index: int = 255,
               mask: Optional[np.ndarray] = None,
               scale: int = 1,
               background: Sequence[int] = BACKGROUND,
               name: str = 'occupancy',
               forward: str = '+x') -> np.ndarray:
    """Render the top-down class-coloured view.

    Args:
        labels (np.ndarray): Shape (X, Y, Z), int.
        palette (np.ndarray): Shape (C, 3), uint8.
        empty_label (int): Label of empty space, not drawn.
        ignore_index (int): Label not drawn. Defaults to 255.
        mask (np.ndarray, optional): Voxels to draw, Shape (X, Y, Z).
            Defaults to None (all).
        scale (int): Pixels per voxel side. Defaults to 1.
        background (Sequence[int]): RGB of empty columns. Defaults to
            white.
        name (str): Named in errors. Defaults to 'occupancy'.
        forward (str): Grid direction ahead of the car, drawn up (see
            :mod:`.orientation`). Defaults to '+x'.

    Returns:
        np.ndarray: Shape (X * scale, Y * scale, 3) (``forward`` along x)
        or (Y * scale, X * scale, 3) (along y), uint8.
    """
    drawn = occupied_voxels(labels, len(palette), empty_label, ignore_index,
                            mask, name)
    top = top_labels(labels, drawn)
    colours = np.empty(top.shape + (3, ), dtype=np.uint8)
    colours[...] = np.asarray(background, dtype=np.uint8)
    seen = top >= 0
    colours[seen] = palette[top[seen]]
    return columns_to_image(colours, scale, forward)
