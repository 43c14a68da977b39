"""Render a model's output data sample: the glue of the hook and the CLI.

A data sample (``Det3DDataSample``, any ``BaseDataElement`` or a plain
dict) carries ``pred_occ`` and / or ``gt_occ`` (Shape (X, Y, Z)), maybe
``mask_camera``, and the metainfo that :class:`~projects.occ_common.
transforms.PackOccInputs` packs: ``sample_idx``, ``lidar2img``,
``occ_pc_range``, ``occ_voxel_size``, and ``lidar2ego`` / ``occ_format``,
which tell the direction ahead of the car (:mod:`.orientation`).
"""
from typing import Optional, Sequence

import numpy as np
import torch

from ..fileio.safe_names import safe_file_name
from .occ_figure import render_occ_figure
from .orientation import sample_forward


def sample_field(sample, key: str, default=None):
    """``key`` of a data element (data or metainfo) or of a dict."""
    if isinstance(sample, dict):
        return sample.get(key, default)
    return getattr(sample, key, default)


def sample_label(sample, fallback: str) -> str:
    """The name of a sample as its metainfo gives it, for titles.

    ``<scene_name>_<token>`` when the metainfo has both (the packed nuScenes
    and synthetic samples: ``scene-0061_ca9a282c9e77460f8360f564131a8af5``),
    ``<token>`` without a scene name, else the ``sample_idx`` (the index in
    the info file, or a saved grid's file name), else ``fallback``.

    Args:
        sample (BaseDataElement | dict): A data sample or a dict.
        fallback (str): The name of a sample that carries none.

    Returns:
        str: The name, unchecked (see :func:`sample_name` for files).
    """
    token = sample_field(sample, 'token')
    if token is not None:
        scene = sample_field(sample, 'scene_name')
        return str(token) if scene is None else f'{scene}_{token}'
    index = sample_field(sample, 'sample_idx')
    return fallback if index is None else str(index)


def sample_name(sample, fallback: str) -> str:
    """:func:`sample_label` as a file name, unique within a dataset.

    Args:
        sample (BaseDataElement | dict): A data sample or a dict.
        fallback (str): The name of a sample that carries none.

    Returns:
        str: The name.

    Raises:
        ValueError: If the token or scene name cannot name a file
            (:func:`~projects.occ_common.fileio.safe_names.safe_file_name`).
    """
    return safe_file_name(sample_label(sample, fallback), 'sample name')


def camera_images(img, bgr: bool = True) -> np.ndarray:
    """Multi-view images of a packed sample as RGB uint8.

    Args:
        img (Tensor | np.ndarray): Shape (N, 3, H, W), values 0-255, as
            ``PackOccInputs`` packs them (BGR from ``mmcv.imfrombytes``).
        bgr (bool): Whether the channels are BGR. Defaults to True.

    Returns:
        np.ndarray: Shape (N, H, W, 3), uint8.

    Raises:
        ValueError: If ``img`` is not (N, 3, H, W).
    """
    if torch.is_tensor(img):
        img = img.detach().cpu().numpy()
    img = np.asarray(img)
    if img.ndim != 4 or img.shape[1] != 3:
        raise ValueError('Expected camera images of shape (N, 3, H, W), '
                         f'got {img.shape}.')
    rgb = img.transpose(0, 2, 3, 1)
    if bgr:
        rgb = rgb[..., ::-1]
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8)


def render_data_sample(sample,
                       class_names: Sequence[str],
                       empty_label: int,
                       palette: Optional[np.ndarray] = None,
                       ignore_index: int = 255,
                       img=None,
                       bgr: bool = True,
                       draw_pred: bool = True,
                       draw_gt: bool = True,
                       use_mask: bool = True,
                       **figure_kwargs) -> np.ndarray:
    """The picture of one data sample (:func:`~.occ_figure.render_occ_figure`).

    Args:
        sample (BaseDataElement | dict): See the module docstring.
        class_names (Sequence[str]): Names in label order.
        empty_label (int): Label of empty space.
        palette (np.ndarray, optional): Shape (C, 3). Defaults to the
            class palette.
        ignore_index (int): GT label never drawn. Defaults to 255.
        img (Tensor, optional): The sample's packed images, Shape
            (N, 3, H, W); drawn with the occupancy projected onto them if
            the metainfo has ``lidar2img``, ``occ_pc_range`` and
            ``occ_voxel_size``. Defaults to None.
        bgr (bool): Whether ``img`` is BGR. Defaults to True.
        draw_pred (bool): Draw ``pred_occ``. Defaults to True.
        draw_gt (bool): Draw ``gt_occ``. Defaults to True.
        use_mask (bool): Draw and count only ``mask_camera`` voxels when
            the sample has one. Defaults to True.
        **figure_kwargs: Passed on (``view_size``, ``azimuth``, ...);
            ``forward`` defaults to the sample's (its ``lidar2ego``, else
            its ``occ_format``'s frame).

    Returns:
        np.ndarray: Shape (H, W, 3), uint8.

    Raises:
        ValueError: If the sample has neither grid to draw.
    """
    pred = sample_field(sample, 'pred_occ') if draw_pred else None
    gt = sample_field(sample, 'gt_occ') if draw_gt else None
    name = sample_label(sample, '?')
    if pred is None and gt is None:
        raise ValueError(f'Sample {name} has no pred_occ or gt_occ to draw '
                         f'(draw_pred={draw_pred}, draw_gt={draw_gt}).')
    mask = sample_field(sample, 'mask_camera') if use_mask else None
    voxel_size = sample_field(sample, 'occ_voxel_size')
    pc_range = sample_field(sample, 'occ_pc_range')
    lidar2img = sample_field(sample, 'lidar2img')
    figure_kwargs.setdefault(
        'forward',
        sample_forward(
            sample_field(sample, 'lidar2ego'),
            sample_field(sample, 'occ_format')))
    images = None
    geometry = (lidar2img, pc_range, voxel_size)
    if img is not None and all(v is not None for v in geometry):
        images = camera_images(img, bgr)
        lidar2img = np.asarray(lidar2img, dtype=np.float64)
        # A temporal config packs the previous key frames' views after the
        # current ones (LoadPreviousKeyFrames), and lidar2img projects into
        # the current views only: draw those.
        if len(images) > len(lidar2img) and len(images) % len(lidar2img) == 0:
            images = images[:len(lidar2img)]
    return render_occ_figure(
        pred,
        gt,
        class_names=class_names,
        palette=palette,
        empty_label=empty_label,
        ignore_index=ignore_index,
        mask=mask,
        voxel_size=(1.0, 1.0, 1.0) if voxel_size is None else voxel_size,
        images=images,
        lidar2img=lidar2img if images is not None else None,
        point_cloud_range=pc_range,
        title=f'sample {name}',
        **figure_kwargs)
