"""Samples to export a graph with and to verify it on, and its inputs.

A graph is exported with one sample and verified on others
(docs/export.md): synthetic ones of the config's shapes, with other point
counts and, for all but seed 0, another camera rig
(:func:`recalibrate`), and real ones read from an info file through the
config's test pipeline, as ``demo/occ_demo.py`` reads them. Every sample
is a collated batch of one, as the dataloader gives it, so that PyTorch's
reference runs the model's own ``data_preprocessor`` and ``_forward``.
"""
import copy
import math
import os.path as osp
from collections import OrderedDict
from typing import Dict, Optional

import numpy as np
import torch
from mmengine.config import Config
from mmengine.dataset import pseudo_collate
from torch import Tensor, nn

#: Graph inputs of a camera model, in this order.
CAMERA_INPUTS = ('imgs', 'points', 'cam2img', 'lidar2cam', 'img_aug_matrix',
                 'lidar2img')
#: Metainfo matrices a recalibration rewrites.
CAMERA_KEYS = ('cam2img', 'lidar2cam', 'img_aug_matrix', 'lidar2img')


def _rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Rotation about z, then y, then x (radians). Shape (3, 3)."""
    cz, sz = math.cos(yaw), math.sin(yaw)
    cy, sy = math.cos(pitch), math.sin(pitch)
    cx, sx = math.cos(roll), math.sin(roll)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return rz @ ry @ rx


def recalibrate(metainfo: dict, seed: int) -> Dict[str, np.ndarray]:
    """Another camera rig for a sample, drawn from ``seed``.

    Each camera of the rig is turned by a common yaw (any angle) and its
    own pitch and roll (up to 4 degrees), moved by up to 0.5 m, gets its
    focal length scaled by 0.8-1.25 and its principal point moved by up to
    5 % of the image, and an image augmentation (scale 0.9-1.1, a shift of
    up to 10 px, a rotation of up to 5 degrees, a horizontal flip for
    half of them) as ``MultiViewImageAug`` composes it. ``lidar2img`` is
    their product, as ``refresh_lidar2img`` forms it.

    Args:
        metainfo (dict): With ``cam2img``, ``lidar2cam``,
            ``img_aug_matrix`` (N, 4, 4) and ``img_shape`` (H, W).
        seed (int): Of the random draw.

    Returns:
        dict[str, np.ndarray]: The four matrices, float32, each
        Shape (N, 4, 4).
    """
    from projects.occ_common.transforms.image_aug import affine_to_4x4
    gen = np.random.default_rng(seed)
    cam2img = np.asarray(metainfo['cam2img'], np.float64).copy()
    lidar2cam = np.asarray(metainfo['lidar2cam'], np.float64).copy()
    aug = np.asarray(metainfo['img_aug_matrix'], np.float64).copy()
    height, width = metainfo['img_shape'][:2]
    yaw = gen.uniform(-math.pi, math.pi)
    for k in range(len(cam2img)):
        # Turn the world under the camera: lidar2cam @ inv(motion).
        motion = np.eye(4)
        motion[:3, :3] = _rotation(yaw, *gen.uniform(-0.07, 0.07, 2))
        motion[:3, 3] = gen.uniform(-0.5, 0.5, 3)
        lidar2cam[k] = lidar2cam[k] @ np.linalg.inv(motion)
        cam2img[k, :2, :2] *= gen.uniform(0.8, 1.25)
        cam2img[k, 0, 2] += gen.uniform(-0.05, 0.05) * width
        cam2img[k, 1, 2] += gen.uniform(-0.05, 0.05) * height
        scale = gen.uniform(0.9, 1.1)
        angle = math.radians(gen.uniform(-5, 5))
        pixel = np.eye(3)
        pixel[:2, :2] = scale * np.array([[math.cos(angle), -math.sin(angle)],
                                          [math.sin(angle), math.cos(angle)]])
        pixel[:2, 2] = gen.uniform(-10, 10, 2)
        if gen.random() < 0.5:
            pixel = np.array([[-1, 0, width], [0, 1, 0], [0, 0, 1]]) @ pixel
        aug[k] = affine_to_4x4(pixel) @ aug[k]
    out = dict(cam2img=cam2img, lidar2cam=lidar2cam, img_aug_matrix=aug,
               lidar2img=aug @ cam2img @ lidar2cam)
    return {key: value.astype(np.float32) for key, value in out.items()}


def synthetic_sample(cfg: Config,
                     seed: int = 0,
                     num_points: Optional[int] = None,
                     recalibrated: Optional[bool] = None) -> dict:
    """A synthetic collated batch of one sample of the config's shapes.

    Args:
        cfg (Config): The config.
        seed (int): Of the images, points and rig. Defaults to 0.
        num_points (int, optional): Points of the cloud. Defaults to
            ``1000 + 500 * seed`` (a count per seed, so that a graph
            exported with seed 0 is checked on other counts).
        recalibrated (bool, optional): Draw another rig
            (:func:`recalibrate`). Defaults to ``seed != 0``.

    Returns:
        dict: ``inputs`` and ``data_samples``, as the dataloader gives
        them.
    """
    from projects.occ_common.synthetic.synthetic_batch import synthetic_batch
    if num_points is None:
        num_points = 1000 + 500 * int(seed)
    batch, _ = synthetic_batch(cfg, 1, int(num_points), seed=int(seed))
    if recalibrated is None:
        recalibrated = seed != 0
    if recalibrated:
        for sample in batch['data_samples']:
            sample.set_metainfo(recalibrate(sample.metainfo, seed))
    return batch


def info_file_sample(cfg: Config,
                     info_file: str,
                     tmp_dir: str,
                     sample_idx: Optional[int] = None,
                     sample_token: Optional[str] = None,
                     data_root: Optional[str] = None) -> dict:
    """One sample of an info file through the config's test pipeline.

    As ``demo/occ_demo.py`` reads it: this library's info files, or an
    mmdet3d v2 info file whose chosen sample is converted on the way
    (:func:`~projects.occ_common.datasets.single_sample.sample_info_file`);
    no labels are needed.

    Args:
        cfg (Config): The config.
        info_file (str): The info file.
        tmp_dir (str): Where a converted one-sample info file may go.
        sample_idx (int, optional): Which sample. Defaults to 0.
        sample_token (str, optional): Or the sample's token.
        data_root (str, optional): Root of the file's paths. Defaults to
            its folder.

    Returns:
        dict: ``inputs`` and ``data_samples`` of one sample, collated.
    """
    from projects.occ_common.apis.unlabelled_pipeline import \
        unlabelled_test_dataset
    from projects.occ_common.datasets.single_sample import sample_info_file
    data_root = data_root or osp.dirname(osp.abspath(info_file))
    sample = sample_info_file(info_file, data_root, tmp_dir, sample_idx,
                              sample_token)
    dataset = unlabelled_test_dataset(cfg, sample.info_file, data_root)
    return pseudo_collate([dataset[sample.index]])


def camera_feeds(batch: dict) -> 'OrderedDict[str, Tensor]':
    """The graph inputs of a camera model for a collated batch of one.

    Args:
        batch (dict): ``inputs`` with ``img`` (a list of one (N, 3, H, W)
            tensor) and ``points`` (a list of one (P, C) tensor), and one
            data sample with ``cam2img``, ``lidar2cam``, ``img_aug_matrix``
            and ``lidar2img`` in its metainfo.

    Returns:
        OrderedDict[str, Tensor]: :data:`CAMERA_INPUTS`: ``imgs`` (1, N,
        3, H, W) float32 pixel values, ``points`` (P, C) and the four
        matrices (1, N, 4, 4), float32.
    """
    inputs, samples = batch['inputs'], batch['data_samples']
    if len(samples) != 1 or len(inputs['img']) != 1:
        raise ValueError('camera_feeds takes a batch of one sample, got '
                         f'{len(samples)}')
    meta = samples[0].metainfo
    feeds = OrderedDict(
        imgs=torch.as_tensor(inputs['img'][0]).float()[None],
        points=torch.as_tensor(inputs['points'][0]).float())
    for key in CAMERA_INPUTS[2:]:
        feeds[key] = torch.as_tensor(
            np.asarray(meta[key]), dtype=torch.float32)[None]
    return feeds


def reference_logits(model: nn.Module, batch: dict) -> Tensor:
    """PyTorch's occupancy logits of a batch: the model's own
    ``data_preprocessor`` and ``_forward`` on its default code path (the
    finest scale of a model that predicts several).

    Returns:
        Tensor: Shape (B, num_classes, X, Y, Z).
    """
    with torch.no_grad():
        data = model.data_preprocessor(copy.copy(batch), False)
        logits = model._forward(data['inputs'], data['data_samples'])
    return logits[0] if isinstance(logits, (list, tuple)) else logits


def config_time_dim(cfg: Config) -> Optional[int]:
    """Column of the points' time lag that the config's test pipeline
    gives (``points_time_dim`` of ``LoadOccPointsFromMultiSweeps``).

    Returns:
        int | None: ``use_dim.index(4)``, or None where the pipeline loads
        no sweeps' time column.
    """
    from projects.occ_common.apis.unlabelled_pipeline import innermost_dataset
    dataset = innermost_dataset(cfg.test_dataloader.dataset)
    for step in dataset.get('pipeline', []):
        if step.get('type') == 'LoadOccPointsFromMultiSweeps':
            use_dim = list(step.get('use_dim', (0, 1, 2, 3, 4)))
            return use_dim.index(4) if 4 in use_dim else None
    return None
