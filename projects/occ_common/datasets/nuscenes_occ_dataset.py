"""nuScenes with SurroundOcc or Occ3D occupancy labels."""
import copy
import os.path as osp
from typing import Callable, List, Optional, Sequence, Union

import numpy as np
from mmdet3d.registry import DATASETS
from mmengine.dataset import BaseDataset
from mmengine.fileio import load

from .info_format import CAMERA_NAMES, check_info_file
from .occ_formats import IGNORE_INDEX, OCC_FORMATS


@DATASETS.register_module()
class NuScenesOccDataset(BaseDataset):
    """nuScenes key frames with multi-view images, sweeps and occupancy GT.

    Reads the info files of ``tools/create_data.py`` (refusing any other
    ``info_version``) and hands each sample to the pipeline with absolute
    paths and numpy matrices. Which occupancy label a sample carries is set
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
        cam_names (Sequence[str]): Cameras kept per sample. Defaults to the
            six nuScenes cameras in mmdet3d's order.
        filter_empty_gt (bool): Outside ``test_mode``, drop samples without
            a label of ``occ_format``. Defaults to True.
        load_interval (int): Keep every ``load_interval``-th sample.
            Defaults to 1.
        test_mode (bool): Evaluation mode. Defaults to False.
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
                 cam_names: Sequence[str] = CAMERA_NAMES,
                 filter_empty_gt: bool = True,
                 load_interval: int = 1,
                 test_mode: bool = False,
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
        self.occ_format = occ_format
        self.coord_frame = coord_frame
        self.cam_names = tuple(cam_names)
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
            ValueError: It is not an info file of this converter version.
        """
        if self.backend_args is None and not osp.isfile(self.ann_file):
            raise FileNotFoundError(
                f'info file not found: {self.ann_file}; create it with '
                'tools/create_data.py nuscenes --root-path <nuScenes root>')
        infos = load(self.ann_file, backend_args=self.backend_args)
        check_info_file(infos, self.ann_file)
        self._metainfo.update(self._frame_meta)
        for key, value in infos['metainfo'].items():
            self._metainfo.setdefault(key, value)
        self._metainfo['info_classes'] = infos['metainfo'].get('classes')
        raw = infos['data_list'][::self.load_interval]
        return [self.parse_data_info(copy.deepcopy(info)) for info in raw]

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
        lidar = info['lidar_points']
        lidar['lidar_path'] = self._join('pts', lidar['lidar_path'])
        info['lidar_path'] = lidar['lidar_path']
        info['num_pts_feats'] = lidar['num_pts_feats']
        info['lidar2ego'] = np.asarray(lidar['lidar2ego'], dtype=np.float64)
        info['ego2global'] = np.asarray(info['ego2global'], dtype=np.float64)
        for sweep in info['lidar_sweeps']:
            pts = sweep['lidar_points']
            pts['lidar_path'] = self._join('sweeps', pts['lidar_path'])
        missing = [c for c in self.cam_names if c not in info['images']]
        if missing:
            raise ValueError(f'{self.ann_file}: sample {info["token"]} has '
                             f'no {missing} images; it has '
                             f'{sorted(info["images"])}')
        info['images'] = {
            cam: dict(info['images'][cam],
                      img_path=self._join('img',
                                          info['images'][cam]['img_path']))
            for cam in self.cam_names
        }
        info['pts_semantic_mask_path'] = self._join(
            'pts_semantic_mask', info['pts_semantic_mask_path'])
        for key in ('occ_surroundocc_path', 'occ_occ3d_path'):
            info[key] = self._join('occ', info[key])
        info['occ_path'] = info[f'occ_{self.occ_format}_path']
        info['occ_format'] = self.occ_format
        info['coord_frame'] = self.coord_frame
        info['ann_file'] = self.ann_file
        return info

    def filter_data(self) -> List[dict]:
        """Drop unlabelled samples when training with ``filter_empty_gt``.

        Returns:
            list[dict]: The kept samples.
        """
        if self.test_mode or not self.filter_empty_gt:
            return self.data_list
        return [info for info in self.data_list if info['occ_path']]
