"""One sample as the dataset doctor checks it: the files as they are.

The doctor reads what the info file names, without the pipeline's
augmentation or its refusals: an image whose size is not the one its
calibration belongs to is loaded as it is (so that the calibration check
can say so and measure it), and a file that cannot be read becomes a
*problem* of the sample instead of an exception. Points, labels and
lidarseg go through the library's own readers
(:func:`~projects.occ_common.transforms.points_loading.read_points_file`,
``LoadOccupancyGT``, ``LoadLidarSegLabels``), so the doctor reads exactly
what training reads.
"""
import os.path as osp
from dataclasses import dataclass, field
from typing import List, Optional, Sequence

import mmcv
import numpy as np

from ...datasets.info_format import as_matrix
from ...transforms.ego_points import in_ego_box
from ...transforms.image_loading import check_complete_image
from ...transforms.loading import (LoadLidarSegLabels, LoadOccupancyGT,
                                   read_bytes)
from ...transforms.points_loading import read_points_file


@dataclass
class CameraData:
    """One camera of a sample.

    Args:
        name (str): The camera, e.g. ``CAM_FRONT``.
        img_path (str): Its image file.
        cam2img (np.ndarray): Intrinsics padded to 4x4. Shape (4, 4).
        lidar2cam (np.ndarray): Key-frame LiDAR to camera. Shape (4, 4).
        cam2ego (np.ndarray): Camera to ego. Shape (4, 4).
        recorded_size (tuple, optional): ``(height, width)`` the info says
            the calibration belongs to (None where it does not say).
        image (np.ndarray, optional): RGB, Shape (H, W, 3), uint8; None
            where it could not be read.
        timestamp (float, optional): Seconds.
        recorded_lidar2img (np.ndarray, optional): The info's own
            ``lidar2img`` where it has one. Shape (4, 4).
    """
    name: str
    img_path: str
    cam2img: np.ndarray
    lidar2cam: np.ndarray
    cam2ego: np.ndarray
    recorded_size: Optional[tuple] = None
    image: Optional[np.ndarray] = None
    timestamp: Optional[float] = None
    recorded_lidar2img: Optional[np.ndarray] = None

    @property
    def lidar2img(self) -> np.ndarray:
        """np.ndarray: ``cam2img @ lidar2cam``. Shape (4, 4)."""
        return self.cam2img @ self.lidar2cam


@dataclass
class SampleData:
    """What the checks of one sample read.

    Args:
        index (int): Index in the dataset.
        token (str): Sample token.
        info (dict): The dataset's parsed info (absolute paths).
        points (np.ndarray): Key-frame points, LiDAR frame, the ego's own
            returns removed when the config has an ``ego_box``.
            Shape (P, C).
        lidar2ego (np.ndarray): Shape (4, 4).
        ego2global (np.ndarray): Shape (4, 4).
        cameras (list[CameraData]): The dataset's cameras, in order.
        labels (np.ndarray, optional): The occupancy label grid.
            Shape (X, Y, Z), uint8.
        mask_camera (np.ndarray, optional): Occ3D's mask. Shape (X, Y, Z).
        mask_lidar (np.ndarray, optional): Occ3D's mask. Shape (X, Y, Z).
        lidarseg (np.ndarray, optional): Per point of ``points`` its
            lidarseg class 1..16, 255 where ignored. Shape (P,).
        problems (dict[str, list[str]]): Per check family, what could not
            be read (the sentence names the file).
    """
    index: int
    token: str
    info: dict
    points: np.ndarray
    lidar2ego: np.ndarray
    ego2global: np.ndarray
    cameras: List[CameraData] = field(default_factory=list)
    labels: Optional[np.ndarray] = None
    mask_camera: Optional[np.ndarray] = None
    mask_lidar: Optional[np.ndarray] = None
    lidarseg: Optional[np.ndarray] = None
    problems: dict = field(default_factory=dict)

    def problem(self, family: str, sentence: str) -> None:
        """Record that ``family``'s input could not be read."""
        self.problems.setdefault(family, []).append(sentence)


def _pad44(matrix, where: str) -> np.ndarray:
    mat = as_matrix(matrix, [(3, 3), (4, 4)], where)
    out = np.eye(4)
    out[:mat.shape[0], :mat.shape[1]] = mat
    return out


def read_image(path: str, what: str) -> np.ndarray:
    """An image file as RGB uint8, Shape (H, W, 3); errors name the file.

    Raises:
        FileNotFoundError: It does not exist.
        ValueError: It is empty, truncated or cannot be decoded.
    """
    raw = read_bytes(path, what, None)
    check_complete_image(raw, path, what)
    image = mmcv.imfrombytes(raw, flag='color', channel_order='rgb')
    if image is None:
        raise ValueError(f'{what} cannot be decoded: {path}')
    return image


def _cameras(sample: SampleData, with_images: bool) -> None:
    for name, entry in sample.info['images'].items():
        where = f'sample {sample.token} {name}'
        camera = CameraData(
            name=name, img_path=entry['img_path'],
            cam2img=_pad44(entry['cam2img'], f'{where} cam2img'),
            lidar2cam=_pad44(entry['lidar2cam'], f'{where} lidar2cam'),
            cam2ego=_pad44(entry['cam2ego'], f'{where} cam2ego'),
            timestamp=entry.get('timestamp'))
        if entry.get('lidar2img') is not None:
            camera.recorded_lidar2img = _pad44(entry['lidar2img'],
                                               f'{where} lidar2img')
        if entry.get('height') is not None and entry.get('width') is not None:
            camera.recorded_size = (int(entry['height']),
                                    int(entry['width']))
        if with_images:
            try:
                camera.image = read_image(
                    entry['img_path'], f'{name} image of sample '
                    f'{sample.token}')
            except (OSError, ValueError) as err:
                sample.problem('calibration', str(err))
        sample.cameras.append(camera)


def _labels(sample: SampleData, occ_format: str) -> None:
    path = sample.info.get('occ_path')
    if path is None:
        return
    try:
        out = LoadOccupancyGT(occ_format=occ_format)(
            dict(occ_path=path, occ_format=occ_format, token=sample.token))
    except (OSError, ValueError) as err:
        sample.problem('labels_vs_lidar', str(err))
        return
    sample.labels = out['gt_occ']
    sample.mask_camera = out.get('mask_camera')
    sample.mask_lidar = out.get('mask_lidar')


def _lidarseg(sample: SampleData, kept: np.ndarray,
              not_own: np.ndarray) -> None:
    """Labels of the finite rows ``kept`` of the file, then of the points
    not on the car (``not_own`` of those)."""
    path = sample.info.get('pts_semantic_mask_path')
    if path is None:
        return
    try:
        out = LoadLidarSegLabels()(
            dict(pts_semantic_mask_path=path, points_kept_rows=kept,
                 token=sample.token, lidar_path=sample.info['lidar_path']))
    except (OSError, ValueError) as err:
        sample.problem('labels_vs_lidar', str(err))
        return
    sample.lidarseg = out['pts_semantic_mask'][not_own]


def load_sample(dataset, index: int, with_images: bool = True,
                ego_box: Optional[Sequence[float]] = None) -> SampleData:
    """Read one sample of a built dataset.

    Args:
        dataset (NuScenesOccDataset): The split's dataset.
        index (int): Sample index.
        with_images (bool): Decode the camera images. Defaults to True.
        ego_box (Sequence[float], optional): The config's ego box: points
            inside are the car's own returns, left out (labels have no
            car). Defaults to None (all points kept).

    Returns:
        SampleData: The sample; what could not be read is in
        ``problems``. A key frame that cannot be read leaves no points.
    """
    info = dataset.get_data_info(index)
    token = info['token']
    lidar2ego = np.asarray(info['lidar2ego'], np.float64)
    sample = SampleData(index=index, token=token, info=info,
                        points=np.zeros((0, 3), np.float32),
                        lidar2ego=lidar2ego,
                        ego2global=np.asarray(info['ego2global'],
                                              np.float64))
    raw = None
    try:
        raw = read_points_file(
            info['lidar_path'], int(info['num_pts_feats']),
            f'LiDAR key frame of sample {token}', drop_nonfinite=False)
    except (OSError, ValueError) as err:
        sample.problem('sequence', str(err))
    if raw is not None:
        kept = np.isfinite(raw).all(axis=1)
        own = np.zeros(len(raw), bool)
        if ego_box is not None:
            own[kept] = in_ego_box(raw[kept, :3], lidar2ego, ego_box)
        sample.points = raw[kept & ~own]
        _lidarseg(sample, kept, ~own[kept])
    _cameras(sample, with_images)
    _labels(sample, dataset.occ_format)
    return sample


def prefixed(dataset, key: str, path: Optional[str]) -> Optional[str]:
    """``path`` of an info file joined to the dataset's ``data_prefix``
    folder ``key`` (``'pts'``, ``'img'``, ...), as the dataset joins it."""
    if path is None:
        return None
    return osp.join(dataset.data_prefix.get(key, ''), path)
