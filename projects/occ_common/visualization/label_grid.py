"""Validation of the label grids handed to the renderers."""
from typing import Optional

import numpy as np
import torch


def as_label_grid(value, name: str = 'occupancy') -> np.ndarray:
    """An integer label grid as a numpy array.

    Args:
        value (np.ndarray | Tensor | list): Labels. Shape (X, Y, Z).
        name (str): What the grid is (``'pred_occ'``, a file name), named
            in errors. Defaults to 'occupancy'.

    Returns:
        np.ndarray: Shape (X, Y, Z), int64.

    Raises:
        ValueError: If ``value`` is not a 3-D integer grid.
    """
    if torch.is_tensor(value):
        value = value.detach().cpu().numpy()
    array = np.asarray(value)
    if array.ndim != 3:
        raise ValueError(f'{name}: expected a label grid of shape (X, Y, Z),'
                         f' got shape {array.shape}.')
    if not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f'{name}: expected integer labels, got dtype '
                         f'{array.dtype}.')
    return array.astype(np.int64, copy=False)


def as_mask(value, shape, name: str = 'mask') -> Optional[np.ndarray]:
    """A boolean voxel mask (e.g. Occ3D's ``mask_camera``) or None.

    Args:
        value (np.ndarray | Tensor, optional): Shape (X, Y, Z).
        shape (tuple[int]): Shape the mask must have.
        name (str): Named in errors. Defaults to 'mask'.

    Returns:
        np.ndarray | None: Shape (X, Y, Z), bool; None if ``value`` is.

    Raises:
        ValueError: If the mask's shape is not ``shape``.
    """
    if value is None:
        return None
    if torch.is_tensor(value):
        value = value.detach().cpu().numpy()
    array = np.asarray(value)
    if array.shape != tuple(shape):
        raise ValueError(f'{name}: expected shape {tuple(shape)}, got '
                         f'{array.shape}.')
    return array.astype(bool, copy=False)


def occupied_voxels(labels: np.ndarray,
                    num_classes: int,
                    empty_label: int,
                    ignore_index: int = 255,
                    mask: Optional[np.ndarray] = None,
                    name: str = 'occupancy') -> np.ndarray:
    """Voxels to draw: a class label other than empty, inside the mask.

    Args:
        labels (np.ndarray): Shape (X, Y, Z), int.
        num_classes (int): Labels must be in ``[0, num_classes)`` or
            ``ignore_index``.
        empty_label (int): Label of empty space (SurroundOcc's 0, Occ3D's
            17).
        ignore_index (int): Label of unannotated voxels, never drawn.
            Defaults to 255.
        mask (np.ndarray, optional): Voxels that count, Shape (X, Y, Z).
            Defaults to None (all).
        name (str): Named in errors. Defaults to 'occupancy'.

    Returns:
        np.ndarray: Shape (X, Y, Z), bool.

    Raises:
        ValueError: If a label is outside ``[0, num_classes)`` and not
            ``ignore_index``.
    """
    bad = (labels != ignore_index) & ((labels < 0) |
                                      (labels >= num_classes))
    if bad.any():
        raise ValueError(
            f'{name}: labels {np.unique(labels[bad])[:10].tolist()} are '
            f'outside [0, {num_classes}) and not {ignore_index}; pass the '
            'class names of this grid.')
    occupied = (labels != empty_label) & (labels != ignore_index)
    if mask is not None:
        occupied &= mask
    return occupied
