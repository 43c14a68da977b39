"""The synthetic world's per-pixel classes, as the network sees them.

The generator writes the class rendered at every camera pixel
(:func:`projects.occ_common.synthetic.camera_label_path`). For a
packed sample this module maps them to the 16 occupancy classes, moves
them through the sample's image augmentation (``img_aug_matrix``) and
reduces them to the feature grid: what a 2D semantic head that generalises
from its sparse LiDAR labels to every pixel would predict at best. Tests
and benchmarks use it as that oracle.
"""
import os.path as osp
from typing import Sequence

import cv2
import numpy as np
import torch
from torch import Tensor

from ..datasets.nuscenes_classes import LIDARSEG_RAW_TO_OCC16
from . import camera_label_path


def rendered_classes(data_root: str, img_path: str) -> np.ndarray:
    """Occupancy class (0..16, 0 = sky or ignored) of every pixel.

    Args:
        data_root (str): Root of the synthetic world.
        img_path (str): The image, absolute or relative to ``data_root``.

    Returns:
        np.ndarray: Shape (H0, W0), uint8.
    """
    rel = osp.relpath(img_path, data_root) if osp.isabs(img_path) \
        else img_path
    path = osp.join(data_root, camera_label_path(rel))
    raw = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if raw is None:
        raise FileNotFoundError(f'no rendered class map {path} for image '
                                f'{img_path} (a synthetic world written '
                                'with write_camera_labels=True has one)')
    return LIDARSEG_RAW_TO_OCC16[raw]


def augment_classes(classes: np.ndarray, img_aug_matrix: np.ndarray,
                    img_shape: Sequence[int]) -> np.ndarray:
    """Move a class map through an image augmentation, nearest neighbour.

    Args:
        classes (np.ndarray): Shape (H0, W0).
        img_aug_matrix (np.ndarray): The view's pixel map (its 2D affine
            part is used, as ``MultiViewImageAug`` builds it).
            Shape (4, 4).
        img_shape (Sequence[int]): Augmented (H, W).

    Returns:
        np.ndarray: Shape (H, W); 0 where the source has no pixel.
    """
    mat = np.eye(3)
    mat[:2, :2] = img_aug_matrix[:2, :2]
    mat[:2, 2] = img_aug_matrix[:2, 2]
    # Pixel i covers [i, i + 1); OpenCV puts pixel centres at integers.
    half = np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1]])
    warp = np.linalg.inv(half) @ mat @ half
    height, width = (int(v) for v in img_shape)
    return cv2.warpAffine(
        classes, warp[:2], (width, height), flags=cv2.INTER_NEAREST,
        borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def feature_classes(classes: np.ndarray, stride: int) -> Tensor:
    """The most frequent class of every ``stride`` x ``stride`` patch.

    Args:
        classes (np.ndarray): Shape (H, W), H and W multiples of stride.
        stride (int): Feature stride.

    Returns:
        Tensor: Long. Shape (H / stride, W / stride).
    """
    height, width = classes.shape
    if height % stride or width % stride:
        raise ValueError(f'class map {classes.shape} is not a multiple of '
                         f'the stride {stride}')
    patches = torch.from_numpy(classes.astype(np.int64)).reshape(
        height // stride, stride, width // stride, stride).permute(
            0, 2, 1, 3).reshape(height // stride, width // stride, -1)
    return patches.mode(dim=-1).values


def sample_feature_classes(data_root: str, sample, stride: int) -> Tensor:
    """:func:`feature_classes` of every view of a packed sample.

    Args:
        data_root (str): Root of the synthetic world.
        sample (Det3DDataSample): With ``img_path``, ``img_aug_matrix``
            (N, 4, 4) and ``img_shape`` in its metainfo.
        stride (int): Feature stride.

    Returns:
        Tensor: Long. Shape (N, H / stride, W / stride).
    """
    meta = sample.metainfo
    aug = np.asarray(meta['img_aug_matrix'])
    return torch.stack([
        feature_classes(
            augment_classes(
                rendered_classes(data_root, path), aug[view],
                meta['img_shape']), stride)
        for view, path in enumerate(meta['img_path'])
    ])
