"""OccCylindrical: camera + LiDAR occupancy through cylindrical TPV planes."""
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch
import torch.nn.functional as F
from mmdet3d.models.detectors import Base3DDetector
from mmdet3d.registry import MODELS
from mmdet3d.structures import Det3DDataSample
from mmdet3d.utils import ConfigType, OptConfigType, OptMultiConfig
from torch import Tensor

from projects.occ_common.geometry.depth import depth_bin_values
from projects.occ_common.models.layers import (camera_parameter_vector,
                                               cartesian_to_cylindrical,
                                               create_frustum,
                                               cylindrical_position_embedding,
                                               frustum_to_lidar,
                                               lidar2img_matrix)


def _stack_meta(samples: Sequence[Det3DDataSample], key: str,
                device: torch.device) -> Tensor:
    """Stack a per-sample metainfo matrix into one float32 tensor."""
    values = []
    for i, sample in enumerate(samples):
        if key not in sample.metainfo:
            raise ValueError(f'OccCylindrical: sample '
                             f'{sample.metainfo.get("sample_idx", i)} has no '
                             f'metainfo {key!r}')
        values.append(torch.as_tensor(np.asarray(sample.metainfo[key])))
    return torch.stack(values).to(device=device, dtype=torch.float32)


def _img_shape(sample: Det3DDataSample) -> Tuple[int, int]:
    """``(H, W)`` of the augmented views before padding."""
    shape = sample.metainfo.get('img_shape')
    if shape is None:
        raise ValueError('OccCylindrical: sample '
                         f'{sample.metainfo.get("sample_idx")} has no '
                         'img_shape')
    # Some loaders store one shape per view; the views share one size.
    if isinstance(shape[0], (tuple, list)):
        shape = shape[0]
    return int(shape[0]), int(shape[1])


@MODELS.register_module()
class OccCylindrical(Base3DDetector):
    """OccCylindrical (camera + LiDAR 3D semantic occupancy).

    Steps 1-8 of the paper: the image encoder gives ``V`` (1/16 of the
    input); :class:`DepthNet` gives ``V_depth`` and ``V_context`` (eq. 5)
    with the cylindrical position embedding of every bin's 3D point; the
    LiDAR point branch (eqs. 2-4) samples ``V_context``; TPV-Polar-Fusion
    lifts the pseudo points and max-pools both clouds into a cylinder,
    group-pools it into three planes per modality and fuses them (eqs.
    6-13); a shared Swin + FPN encodes the planes (eqs. 14-16) and the head
    classifies the Cartesian voxels of four scales (eq. 17). The loss is
    eq. 19: the multi-scale occupancy loss plus the LiDAR depth loss.

    Camera geometry comes from each sample's ``lidar2img`` (or
    ``img_aug_matrix @ cam2img @ lidar2cam``). The data pipeline folds the
    BEV augmentation into every ``lidar2*`` matrix, so ``bda_matrix`` is
    not applied again here.

    Args:
        img_encoder (dict): :class:`MultiViewImageEncoder` config.
        depth_net (dict): :class:`DepthNet` config; its
            ``position_channels`` (0 or ``3 * D``) switches the position
            embedding.
        point_branch (dict): :class:`LidarPointBranch` config.
        tpv_fusion (dict): :class:`TPVPolarFusion` config.
        tpv_encoder (dict): :class:`TPVPlaneEncoder` config.
        occ_head (dict): :class:`CylindricalOccHead` config.
        depth_bound (Sequence[float]): ``(min, max, step)`` of the depth
            bins in metres.
        loss_depth (dict, optional): Depth loss (``DepthBCELoss``); None
            removes the depth supervision (Table V). Defaults to None.
        loss_mask_key (str, optional): Data-sample field of a bool mask
            outside which voxels are not supervised (``'mask_camera'`` for
            Occ3D). Defaults to None.
        ignore_index (int): Label given to masked voxels. Defaults to 255.
        data_preprocessor (dict, optional): ``Det3DDataPreprocessor``
            config. Defaults to None.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 img_encoder: ConfigType,
                 depth_net: ConfigType,
                 point_branch: ConfigType,
                 tpv_fusion: ConfigType,
                 tpv_encoder: ConfigType,
                 occ_head: ConfigType,
                 depth_bound: Sequence[float],
                 loss_depth: OptConfigType = None,
                 loss_mask_key: Optional[str] = None,
                 ignore_index: int = 255,
                 data_preprocessor: OptConfigType = None,
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(
            data_preprocessor=data_preprocessor, init_cfg=init_cfg)
        self.img_encoder = MODELS.build(img_encoder)
        self.depth_net = MODELS.build(depth_net)
        self.point_branch = MODELS.build(point_branch)
        self.tpv_fusion = MODELS.build(tpv_fusion)
        self.tpv_encoder = MODELS.build(tpv_encoder)
        self.occ_head = MODELS.build(occ_head)
        self.depth_bound = tuple(float(v) for v in depth_bound)
        self.loss_depth = MODELS.build(loss_depth) if loss_depth else None
        self.loss_mask_key = loss_mask_key
        self.ignore_index = ignore_index
        num_bins = depth_bin_values(self.depth_bound).numel()
        if self.depth_net.num_depth_bins != num_bins:
            raise ValueError(
                f'OccCylindrical: depth_bound {self.depth_bound} gives '
                f'{num_bins} bins but depth_net predicts '
                f'{self.depth_net.num_depth_bins}')

    def extract_feat(self, batch_inputs_dict: dict,
                     batch_data_samples: List[Det3DDataSample]) -> dict:
        """Run the network up to the head's logits.

        Args:
            batch_inputs_dict (dict): ``imgs`` Shape (B, N, 3, H, W) and
                ``points`` list of Shape (P_i, C).
            batch_data_samples (list[Det3DDataSample]): Samples with the
                camera metainfo.

        Returns:
            dict: ``logits`` (list per scale, finest first, each
            Shape (B, K, X_l, Y_l, Z_l)) and ``depth`` Shape (B*N, D, h, w).
        """
        imgs = batch_inputs_dict.get('imgs')
        points = batch_inputs_dict.get('points')
        if imgs is None or points is None:
            raise ValueError('OccCylindrical needs inputs "imgs" and '
                             f'"points", got {sorted(batch_inputs_dict)}')
        if len(batch_data_samples) != imgs.shape[0]:
            raise ValueError(f'OccCylindrical: {imgs.shape[0]} image sets '
                             f'for {len(batch_data_samples)} data samples')
        batch_size, num_cams = imgs.shape[:2]
        input_shape = tuple(imgs.shape[-2:])
        lidar2img = self._lidar2img(batch_data_samples, imgs.device)
        if lidar2img.shape[1] != num_cams:
            raise ValueError(f'OccCylindrical: {num_cams} images but '
                             f'{lidar2img.shape[1]} camera matrices')

        feats = self.img_encoder(imgs)
        frustum = create_frustum(input_shape, feats.shape[-2:],
                                 self.depth_bound)
        cam_points = frustum_to_lidar(frustum, lidar2img)
        pos_embed = cam_params = None
        if self.depth_net.position_channels > 0:
            pos_embed = cylindrical_position_embedding(
                cam_points, self.tpv_fusion.grid.cyl_range)
        if self.depth_net.camera_param_dims > 0:
            cam_params = camera_parameter_vector(
                *(_stack_meta(batch_data_samples, key, imgs.device)
                  for key in ('cam2img', 'lidar2cam', 'img_aug_matrix')))
            cam_params = cam_params.flatten(0, 1)
        out = self.depth_net(feats, pos_embed, cam_params)
        depth, context = out['depth'], out['context']

        # Points outside the cylinder could not reach any voxel.
        points = [self._inside(p) for p in points]
        lidar_feats = self.point_branch(
            points, context.unflatten(0, (batch_size, num_cams)), lidar2img,
            input_shape, [_img_shape(s) for s in batch_data_samples])
        planes = self.tpv_fusion(depth, context, cam_points, lidar_feats,
                                 [p[:, :3] for p in points])
        logits = self.occ_head(self.tpv_encoder(planes))
        return dict(logits=logits, depth=depth)

    def _inside(self, points: Tensor) -> Tensor:
        """Keep the points that fall in the cylinder. Shape (P', C)."""
        cyl = cartesian_to_cylindrical(points[:, :3])
        return points[self.tpv_fusion.grid.voxel_coords(cyl)[1]]

    @staticmethod
    def _lidar2img(samples: Sequence[Det3DDataSample],
                   device: torch.device) -> Tensor:
        """Full projection per view. Shape (B, N, 4, 4)."""
        if all('lidar2img' in s.metainfo for s in samples):
            return _stack_meta(samples, 'lidar2img', device)
        return lidar2img_matrix(
            *(_stack_meta(samples, key, device)
              for key in ('cam2img', 'lidar2cam', 'img_aug_matrix')))

    def _stack_field(self, samples: Sequence[Det3DDataSample],
                     key: str) -> Tensor:
        """Stack a per-sample tensor field, naming the sample if missing."""
        values = []
        for i, sample in enumerate(samples):
            if key not in sample:
                raise ValueError(
                    'OccCylindrical: data sample '
                    f'{sample.metainfo.get("sample_idx", i)} has no {key!r}')
            values.append(sample.get(key))
        return torch.stack(values)

    def loss(self, batch_inputs_dict: dict,
             batch_data_samples: List[Det3DDataSample]) -> Dict[str, Tensor]:
        """Eq. 19: multi-scale occupancy loss plus the depth loss.

        Args:
            batch_inputs_dict (dict): See :meth:`extract_feat`.
            batch_data_samples (list[Det3DDataSample]): With ``gt_occ``
                Shape (X, Y, Z) and, for the depth loss, ``gt_depth``
                Shape (N, H, W).

        Returns:
            dict[str, Tensor]: Loss terms.
        """
        out = self.extract_feat(batch_inputs_dict, batch_data_samples)
        device = out['depth'].device
        gt_occ = self._stack_field(batch_data_samples,
                                   'gt_occ').to(device).long()
        if self.loss_mask_key is not None:
            mask = self._stack_field(batch_data_samples,
                                     self.loss_mask_key).to(device).bool()
            gt_occ = gt_occ.masked_fill(~mask, self.ignore_index)
        losses = self.occ_head.loss(out['logits'], gt_occ)
        if self.loss_depth is not None:
            gt_depth = self._stack_field(batch_data_samples,
                                         'gt_depth').to(device).float()
            in_h, in_w = batch_inputs_dict['imgs'].shape[-2:]
            pad_h, pad_w = in_h - gt_depth.shape[-2], in_w - gt_depth.shape[-1]
            if pad_h < 0 or pad_w < 0:
                raise ValueError(
                    f'OccCylindrical: gt_depth {tuple(gt_depth.shape)} is '
                    f'larger than the input images {(in_h, in_w)}')
            # Padded pixels have no LiDAR return (depth 0), like the images.
            gt_depth = F.pad(gt_depth, (0, pad_w, 0, pad_h))
            losses['loss_depth'] = self.loss_depth(out['depth'],
                                                   gt_depth.flatten(0, 1))
        return losses

    def predict(self, batch_inputs_dict: dict,
                batch_data_samples: List[Det3DDataSample]
                ) -> List[Det3DDataSample]:
        """Predict the finest-scale occupancy.

        Args:
            batch_inputs_dict (dict): See :meth:`extract_feat`.
            batch_data_samples (list[Det3DDataSample]): Input samples.

        Returns:
            list[Det3DDataSample]: The input samples with ``pred_occ``
            Shape (X, Y, Z) int64 (their ``gt_occ`` and ``mask_camera``, if
            any, stay in place for the metric).
        """
        out = self.extract_feat(batch_inputs_dict, batch_data_samples)
        pred = self.occ_head.predict(out['logits'])
        for sample, pred_occ in zip(batch_data_samples, pred):
            sample.pred_occ = pred_occ
        return batch_data_samples

    def _forward(self, batch_inputs_dict: dict,
                 batch_data_samples: List[Det3DDataSample]) -> List[Tensor]:
        """Raw logits per scale, finest first (``mode='tensor'``)."""
        return self.extract_feat(batch_inputs_dict,
                                 batch_data_samples)['logits']
