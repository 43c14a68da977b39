"""Packing of occupancy samples into model inputs and data samples."""
from typing import Sequence

import numpy as np
import torch
from mmdet3d.datasets.transforms import Pack3DDetInputs
from mmdet3d.registry import TRANSFORMS

#: Dense per-sample targets set as attributes of the data sample, with the
#: tensor dtype each gets.
OCC_FIELDS = dict(
    gt_occ=torch.long,
    mask_camera=torch.bool,
    mask_lidar=torch.bool,
    gt_depth=torch.float32,
    # uint8 keeps the six full-resolution maps small between processes;
    # losses take ``.long()``.
    gt_seg_2d=torch.uint8)

#: Meta keys packed by default: identity, weather, geometry of every view
#: and of the working frame, what the loading removed or chose (the ego
#: returns, the source of the 2-D semantic targets), and which points column
#: is the sweeps' time lag (``points_time_dim``: models that need the key
#: frame alone, such as SDG-OCC's depth guidance, select it as
#: ``PointsToDepthMaps`` does), and the previous key frames of a temporal
#: sample (``LoadPreviousKeyFrames``).
OCC_META_KEYS = ('sample_idx', 'token', 'scene_token', 'scene_name',
                 'is_rainy', 'is_night', 'timestamp', 'lidar_path',
                 'img_path', 'cam_names', 'num_views', 'ori_shape',
                 'img_shape', 'pad_shape', 'lidar2img', 'cam2img',
                 'lidar2cam', 'cam2ego', 'img_aug_matrix', 'bda_matrix',
                 'lidar2ego', 'ori_lidar2ego', 'ego2global', 'occ_format',
                 'coord_frame', 'occ_pc_range', 'occ_voxel_size',
                 'num_pts_feats', 'img_aug_params', 'bda_params',
                 'num_ego_points', 'seg_2d_source', 'points_time_dim',
                 'prev_tokens', 'prev2curr', 'prev_cam2img',
                 'prev_lidar2cam', 'prev_img_aug_matrix', 'prev_lidar2img',
                 'prev_points')


@TRANSFORMS.register_module()
class PackOccInputs(Pack3DDetInputs):
    """Pack an occupancy sample: inputs, dense targets and metainfo.

    mmdet3d's ``Pack3DDetInputs`` handles ``points`` (P, C) and the views
    (stacked to ``img`` (N, 3, H, W); ``Det3DDataPreprocessor`` batches them
    to ``imgs`` (B, N, 3, H, W)) and ``pts_semantic_mask`` (into
    ``gt_pts_seg``). This subclass adds the dense targets of
    :data:`OCC_FIELDS` as tensor attributes of the ``Det3DDataSample``
    (``gt_occ`` (X, Y, Z) long, ``mask_camera`` / ``mask_lidar`` (X, Y, Z)
    bool, ``gt_depth`` (N, H, W) float32, ``gt_seg_2d`` (N, H, W) uint8)
    and stores 4x4 matrices in the metainfo as float32 arrays.

    Args:
        keys (Sequence[str]): Keys to pack. Defaults to points, img,
            pts_semantic_mask and all of :data:`OCC_FIELDS`; absent keys are
            skipped.
        meta_keys (Sequence[str]): Metainfo keys. Defaults to
            :data:`OCC_META_KEYS`.

    Required Keys:

    - any of ``keys`` and ``meta_keys``

    Added Keys:

    - inputs (dict): ``points`` (Tensor (P, C)), ``img`` (Tensor
      (N, 3, H, W)).
    - data_samples (Det3DDataSample)
    """

    def __init__(self,
                 keys: Sequence[str] = ('points', 'img', 'pts_semantic_mask',
                                        *OCC_FIELDS),
                 meta_keys: Sequence[str] = OCC_META_KEYS) -> None:
        self.occ_keys = tuple(k for k in keys if k in OCC_FIELDS)
        super().__init__(
            keys=tuple(k for k in keys if k not in OCC_FIELDS),
            meta_keys=tuple(meta_keys))

    def pack_single_results(self, results: dict) -> dict:
        """Pack one sample.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: ``inputs`` and ``data_samples``.
        """
        for key, value in list(results.items()):
            if key in self.meta_keys and isinstance(value, np.ndarray) \
                    and value.dtype == np.float64:
                results[key] = value.astype(np.float32)
        packed = super().pack_single_results(results)
        sample = packed['data_samples']
        for key in self.occ_keys:
            if key in results:
                value = np.ascontiguousarray(results[key])
                tensor = torch.from_numpy(value).to(OCC_FIELDS[key])
                sample.set_field(tensor, key)
        return packed

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}(keys={self.keys + self.occ_keys},'
                f' meta_keys={self.meta_keys})')
