"""nuScenes with SurroundOcc or Occ3D occupancy labels."""
import copy
import os.path as osp
from typing import Callable, Dict, List, Optional, Sequence, Union

import numpy as np
from mmdet3d.registry import DATASETS
from mmengine.dataset import BaseDataset
from mmengine.fileio import get_local_path

from ..fileio.safe_pickle import load_info_file
from .augmentation_seed import EpochSeed
from .info_format import CAMERA_NAMES, as_matrix, check_info_file
from .occ_formats import IGNORE_INDEX, OCC_FORMATS
from .sample_checks import (check_previous_time, check_rigid, check_seconds,
                            check_sweep_time)

_MAT44 = [(4, 4)]


def _pose(value, where: str) -> np.ndarray:
    """A 4x4 pose or extrinsic calibration: finite and rigid."""
    return check_rigid(as_matrix(value, _MAT44, where), where)


@DATASETS.register_module()
class NuScenesOccDataset(BaseDataset):
    """nuScenes key frames with multi-view images, sweeps and occupancy GT.

    Reads the info files of ``tools/create_data.py`` through a restricted
    unpickler (refusing any other ``info_version``, and any pickled object
    but containers, scalars and numpy arrays), checks every sample's keys
    and matrices, and hands each sample to the pipeline with absolute
    paths and numpy matrices. In training, each sample's random
    augmentation is seeded by ``(seed, epoch, index)``
    (:mod:`.augmentation_seed`). Which occupancy label a sample carries is set
    by ``occ_format``; the label formats differ in frame and classes:

    * ``'surroundocc'``: LiDAR frame; classes ``empty`` + 16 (17 names).
    * ``'occ3d'``: ego frame; classes ``others`` + 16 + ``free`` (18 names).

    Args:
        data_root (str): Root the info paths are relative to.
        ann_file (str): Info file, relative to ``data_root`` or absolute.
        pipeline (Sequence[dict | Callable]): Transforms. Defaults to ().
        occ_format (str): ``'surroundocc'`` or ``'occ3d'``.
            Defaults to 'surroundocc'.
        coord_frame (str, optional): Working frame, ``'lidar'`` or ``'ego'``.
            It must be the frame of the label format (labels are never
            resampled between frames); the pipeline moves the LiDAR data
            there with ``PointsToEgoFrame`` for Occ3D. Defaults to the
            format's frame.
        data_prefix (dict): Folders (relative to ``data_root``) the info
            paths are joined to: ``pts``, ``sweeps``, ``img``,
            ``pts_semantic_mask``, ``occ``. Defaults to all ``''``.
        cam_names (Sequence[str], optional): Cameras kept per sample, in
            order. None keeps the cameras the info file lists (its
            ``metainfo['cameras']``, e.g. a four-camera rig's). Defaults to
            the six nuScenes cameras in mmdet3d's order.
        filter_empty_gt (bool): Outside ``test_mode``, drop samples without
            a label of ``occ_format``. Defaults to True.
        load_interval (int): Keep every ``load_interval``-th sample.
            Defaults to 1.
        test_mode (bool): Evaluation mode. Defaults to False.
        num_frames (int): Key frames per sample, the current one and
            ``num_frames - 1`` before it; each sample then carries
            ``prev_frames`` (see :meth:`previous_frames`) for
            ``LoadPreviousKeyFrames``. Defaults to 1.
        metainfo (dict, optional): Overrides of the class metainfo.
        backend_args (dict, optional): mmengine file backend arguments for
            the info file. Defaults to None (local files).
        **kwargs: Passed to :class:`mmengine.dataset.BaseDataset`.
    """

    METAINFO = dict(dataset='nuscenes-occ')
    _PREFIX_KEYS = ('pts', 'sweeps', 'img', 'pts_semantic_mask', 'occ')

    def __init__(self,
                 data_root: str,
                 ann_file: str,
                 pipeline: Sequence[Union[dict, Callable]] = (),
                 occ_format: str = 'surroundocc',
                 coord_frame: Optional[str] = None,
                 data_prefix: Optional[dict] = None,
                 cam_names: Optional[Sequence[str]] = CAMERA_NAMES,
                 filter_empty_gt: bool = True,
                 load_interval: int = 1,
                 test_mode: bool = False,
                 num_frames: int = 1,
                 metainfo: Optional[dict] = None,
                 backend_args: Optional[dict] = None,
                 **kwargs) -> None:
        if occ_format not in OCC_FORMATS:
            raise ValueError(f'occ_format must be one of '
                             f'{sorted(OCC_FORMATS)}, got {occ_format!r}')
        spec = OCC_FORMATS[occ_format]
        coord_frame = coord_frame or spec.frame
        if coord_frame != spec.frame:
            raise ValueError(
                f'{occ_format} labels are in the {spec.frame} frame; '
                f'coord_frame={coord_frame!r} would need resampled labels. '
                f'Use coord_frame={spec.frame!r}.')
        if load_interval < 1:
            raise ValueError(f'load_interval must be >= 1, got '
                             f'{load_interval}')
        if num_frames < 1:
            raise ValueError(f'num_frames must be >= 1, got {num_frames}')
        if metainfo is not None and not isinstance(metainfo, dict):
            # mmengine would fail on it with "dictionary update sequence
            # element #0 has length ...", naming nothing.
            raise TypeError(
                f'{type(self).__name__} of {ann_file}: metainfo must be a '
                f'dict such as dict(classes=(...)), got '
                f'{type(metainfo).__name__} {metainfo!r:.60}')
        self.num_frames = int(num_frames)
        self.occ_format = occ_format
        self.coord_frame = coord_frame
        self.cam_names = None if cam_names is None else tuple(cam_names)
        self.filter_empty_gt = filter_empty_gt
        self.load_interval = load_interval
        self.backend_args = backend_args
        prefix = {key: '' for key in self._PREFIX_KEYS}
        prefix.update(data_prefix or {})
        # Only non-string values go through mmengine's metainfo argument,
        # which tries to open every string as a file.
        meta = dict(
            classes=spec.class_names,
            ignore_index=IGNORE_INDEX,
            point_cloud_range=list(spec.point_cloud_range),
            voxel_size=list(spec.voxel_size),
            grid_size=list(spec.grid_size),
            cam_names=self.cam_names)
        meta.update(metainfo or {})
        if len(meta['classes']) != len(spec.class_names):
            raise ValueError(
                f'{occ_format} labels have {len(spec.class_names)} classes '
                f'{spec.class_names}, metainfo gives {len(meta["classes"])}')
        self._frame_meta = dict(occ_format=occ_format, coord_frame=coord_frame)
        self._epoch_seed = EpochSeed()
        super().__init__(
            data_root=data_root,
            ann_file=ann_file,
            metainfo=meta,
            data_prefix=prefix,
            pipeline=list(pipeline),
            test_mode=test_mode,
            **kwargs)

    def load_data_list(self) -> List[dict]:
        """Load and check the info file, then keep every n-th sample.

        Returns:
            list[dict]: Parsed samples (see :meth:`parse_data_info`).

        Raises:
            FileNotFoundError: The info file does not exist.
            ValueError: It is not an info file of this converter version,
                it is empty, truncated or holds no sample, or a sample
                lacks a key or has a malformed matrix (the message names
                the file, the sample and the key).
            RefusedGlobalError: It pickles an object other than
                containers, scalars and numpy arrays (nothing is run).
        """
        if self.backend_args is None and not osp.isfile(self.ann_file):
            raise FileNotFoundError(
                f'info file not found: {self.ann_file}; create it with '
                'tools/create_data.py nuscenes --root-path <nuScenes root>')
        with get_local_path(self.ann_file, self.backend_args) as path:
            infos = load_info_file(path)
        check_info_file(infos, self.ann_file)
        if not infos['data_list']:
            raise ValueError(
                f'{self.ann_file} holds no samples (split '
                f'{infos["metainfo"].get("split")!r} of the scenes '
                f'{infos["metainfo"].get("scenes")}); check the split and '
                '--version given to tools/create_data.py.')
        self._metainfo.update(self._frame_meta)
        if self.cam_names is None:
            self.cam_names = self._info_cameras(infos)
            self._metainfo['cam_names'] = self.cam_names
        for key, value in infos['metainfo'].items():
            self._metainfo.setdefault(key, value)
        self._metainfo['info_classes'] = infos['metainfo'].get('classes')
        raw = infos['data_list'][::self.load_interval]
        parsed = [self.parse_data_info(copy.deepcopy(info)) for info in raw]
        if self.num_frames > 1:
            # The whole file, not every n-th sample: links skip nothing.
            by_token = {e['token']: e for e in infos['data_list']}
            for info in parsed:
                info['prev_frames'] = self.previous_frames(info, by_token)
        return parsed

    def _info_cameras(self, infos: dict) -> tuple:
        """The cameras an info file lists (``cam_names=None``)."""
        cameras = infos['metainfo'].get('cameras')
        if cameras is None:  # written before the converter recorded them
            cameras = list(infos['data_list'][0]['images'])
        if not cameras:
            raise ValueError(f'{self.ann_file}: its samples list no camera;'
                             ' cam_names=None needs at least one')
        return tuple(cameras)

    def previous_frames(self, info: dict,
                        by_token: Dict[str, dict]) -> List[dict]:
        """The ``num_frames - 1`` key frames before ``info``, nearest first.

        Frame t-1 is the sample's ``prev_key_frame`` link; frame t-k the
        link of frame t-(k-1)'s entry in the same file. Where a scene
        starts (the link is None) the earliest frame repeats, the current
        one for a scene's first sample: it then looks like a car that has
        not moved, which is what BEVDet4D feeds at a scene's start.

        Args:
            info (dict): A parsed sample.
            by_token (dict[str, dict]): Raw entries of the info file.

        Returns:
            list[dict]: Per frame ``token``, ``ego2global`` and
            ``lidar2ego`` (4, 4), ``lidar_path``, ``num_pts_feats`` and
            ``images`` (parsed as the sample's own).

        Raises:
            ValueError: If the info file has no ``prev_key_frame`` links
                (written before they existed) or a link's entry is missing.
        """
        where = f'{self.ann_file}: sample {info["token"]}'
        if 'prev_key_frame' not in info:
            raise ValueError(
                f'{where} has no prev_key_frame link, needed by num_frames='
                f'{self.num_frames}; re-create the info file with '
                'tools/create_data.py --overwrite')
        frames, link = [], info['prev_key_frame']
        later = info['timestamp']
        current = dict(token=info['token'], ego2global=info['ego2global'],
                       lidar2ego=info['lidar2ego'],
                       lidar_path=info['lidar_path'],
                       num_pts_feats=info['num_pts_feats'],
                       images=info['images'])
        for k in range(1, self.num_frames):
            if link is None:
                frames.append(frames[-1] if frames else current)
                continue
            frames.append(self._parse_link(link, f'{where} frame t-{k}'))
            # A frame of the past, within the stated gap (sample_checks).
            previous = check_seconds(link.get('timestamp'),
                                     f'{where} frame t-{k} timestamp')
            check_previous_time(previous, later, f'{where} frame t-{k}')
            later = previous
            if k + 1 < self.num_frames:
                if link['token'] not in by_token:
                    raise ValueError(
                        f'{where}: key frame t-{k} ({link["token"]}) is not '
                        f'in the file, so frame t-{k + 1} cannot be found')
                link = by_token[link['token']].get('prev_key_frame')
        return frames

    def _parse_link(self, link: dict, where: str) -> dict:
        """A ``prev_key_frame`` link with absolute paths and matrices."""
        lidar = self._entry(link, 'lidar_points',
                            ('lidar_path', 'num_pts_feats', 'lidar2ego'),
                            where)
        return dict(
            token=link['token'],
            ego2global=_pose(link['ego2global'], f'{where} ego2global'),
            lidar2ego=_pose(lidar['lidar2ego'],
                            f'{where} lidar_points.lidar2ego'),
            lidar_path=self._join('pts', lidar['lidar_path']),
            num_pts_feats=lidar['num_pts_feats'],
            images=self._parse_images(link, where))

    def _join(self, key: str, path: Optional[str]) -> Optional[str]:
        return None if path is None else osp.join(self.data_prefix[key], path)

    def parse_data_info(self, info: dict) -> dict:
        """Absolute paths and numpy matrices for the pipeline.

        Adds ``lidar_path``, ``num_pts_feats``, ``lidar2ego`` (4, 4),
        ``ego2global`` (4, 4), ``occ_path`` (label of ``occ_format`` or
        None), ``occ_format``, ``coord_frame`` and ``ann_file`` (for
        error messages); keeps only ``cam_names`` in ``images``.

        Args:
            info (dict): One raw ``data_list`` entry.

        Returns:
            dict: The entry with the keys above.
        """
        where = f'{self.ann_file}: sample {info["token"]}'
        lidar = self._entry(info, 'lidar_points',
                            ('lidar_path', 'num_pts_feats', 'lidar2ego'),
                            where)
        lidar['lidar_path'] = self._join('pts', lidar['lidar_path'])
        info['lidar_path'] = lidar['lidar_path']
        info['num_pts_feats'] = lidar['num_pts_feats']
        info['lidar2ego'] = _pose(lidar['lidar2ego'],
                                  f'{where} lidar_points.lidar2ego')
        info['ego2global'] = _pose(info['ego2global'], f'{where} ego2global')
        key_time = check_seconds(info['timestamp'], f'{where} timestamp')
        for i in range(len(info['lidar_sweeps'])):
            name = f'{where} lidar_sweeps[{i}]'
            sweep = self._entry(info['lidar_sweeps'], i,
                                ('lidar_points', 'timestamp'), name)
            check_sweep_time(
                check_seconds(sweep['timestamp'], f'{name}.timestamp'),
                key_time, name)
            pts = self._entry(sweep, 'lidar_points', ('lidar_path', ), name)
            key = 'sensor2lidar' if 'sensor2lidar' in pts else 'lidar2sensor'
            if key not in pts:
                raise ValueError(f'{name}: lidar_points needs sensor2lidar '
                                 f'or lidar2sensor; it has {sorted(pts)}')
            pts[key] = _pose(pts[key], f'{name}.lidar_points.{key}')
            pts['lidar_path'] = self._join('sweeps', pts['lidar_path'])
        info['images'] = self._parse_images(info, where)
        info['pts_semantic_mask_path'] = self._join(
            'pts_semantic_mask', info['pts_semantic_mask_path'])
        for key in ('occ_surroundocc_path', 'occ_occ3d_path'):
            info[key] = self._join('occ', info[key])
        info['occ_path'] = info[f'occ_{self.occ_format}_path']
        info['occ_format'] = self.occ_format
        info['coord_frame'] = self.coord_frame
        info['ann_file'] = self.ann_file
        return info

    def _parse_images(self, info: dict, where: str) -> Dict[str, dict]:
        """The ``cam_names`` views of an entry (or link) with absolute
        paths and numpy matrices."""
        missing = [c for c in self.cam_names if c not in info['images']]
        if missing:
            raise ValueError(f'{self.ann_file}: sample {info["token"]} has '
                             f'no {missing} images; it has '
                             f'{sorted(info["images"])}')
        images = {}
        for cam in self.cam_names:
            image = dict(self._entry(info['images'], cam,
                                     ('img_path', 'cam2img', 'lidar2cam',
                                      'cam2ego'), f'{where} images'))
            image['img_path'] = self._join('img', image['img_path'])
            image['cam2img'] = as_matrix(image['cam2img'], [(3, 3), (4, 4)],
                                         f'{where} images.{cam}.cam2img')
            for key in ('lidar2cam', 'cam2ego'):
                image[key] = _pose(image[key], f'{where} images.{cam}.{key}')
            images[cam] = image
        return images

    @staticmethod
    def _entry(container, key, required, where: str) -> dict:
        """``container[key]``, a dict holding the ``required`` keys."""
        try:
            entry = container[key]
        except (KeyError, IndexError):
            raise ValueError(f'{where}: missing {key!r}') from None
        if not isinstance(entry, dict):
            raise ValueError(f'{where}: {key!r} must be a dict, got '
                             f'{type(entry).__name__}')
        missing = [k for k in required if k not in entry]
        if missing:
            raise ValueError(f'{where}: {key} lacks the keys {missing}; it '
                             f'has {sorted(entry)}')
        return entry

    def filter_data(self) -> List[dict]:
        """Drop unlabelled samples when training with ``filter_empty_gt``.

        Returns:
            list[dict]: The kept samples.

        Raises:
            ValueError: If no sample is left.
        """
        if self.test_mode or not self.filter_empty_gt:
            return self.data_list
        kept = [info for info in self.data_list if info['occ_path']]
        if not kept:
            raise ValueError(
                f'{self.ann_file}: none of its {len(self.data_list)} samples '
                f'(every {self.load_interval}-th) has a {self.occ_format} '
                'occupancy label, and filter_empty_gt drops unlabelled '
                'samples in training; point tools/create_data.py at the '
                f'{self.occ_format} labels (--surroundocc-root / '
                '--occ3d-root).')
        return kept

    def set_augmentation_seed(self, seed: int, epoch: int) -> None:
        """Seed the random augmentations of ``epoch`` (see
        :mod:`.augmentation_seed`); called by ``AugmentationSeedHook``.

        Args:
            seed (int): The run's seed.
            epoch (int): The 0-based epoch about to start.
        """
        self._epoch_seed.set(seed, epoch)

    def prepare_data(self, idx: int):
        """Run the pipeline with the random state of sample ``idx``.

        Args:
            idx (int): Sample index.

        Returns:
            dict: The pipeline's output.
        """
        with self._epoch_seed.context(idx):
            return super().prepare_data(idx)
