"""SPVCNN pre-training on nuScenes-lidarseg, SDG-OCC's LiDAR-side start.

The paper does not say how its SPVCNN starts; the authors' release loads
a checkpoint of it trained for LiDAR segmentation (``best_iou_635_4.pth``)
and keeps a point segmentation loss (times 0.1) while training the
occupancy model. :class:`SPVCNNSegmentor` is that pre-training: the
SDG-OCC configs' ``SPVCNNEncoder`` without its BEV projection and a
:class:`~projects.occ_common.models.sparse.PointSegHead`; its checkpoint
loads into the occupancy model's ``lidar_encoder`` through the checked
``pretrained`` entry
(``configs/sdg_occ/pretrain/spvcnn_4xb4-24e_nus-lidarseg.py``).
"""
from typing import Dict, List, Optional, Sequence

import torch
from mmdet3d.registry import MODELS
from mmdet3d.structures import PointData
from mmengine.model import BaseModel
from torch import Tensor

from projects.occ_common.models.sparse.point_seg_head import \
    gather_point_labels


@MODELS.register_module()
class SPVCNNSegmentor(BaseModel):
    """Point segmentation with ``SPVCNNEncoder`` point features.

    Args:
        lidar_encoder (dict): ``SPVCNNEncoder``, with ``bev_output=False``
            (its BEV projection would get no gradient).
        point_seg_head (dict): ``PointSegHead``; its ``in_channels`` default
            to the encoder's point channels.
        data_preprocessor (dict, optional): ``Det3DDataPreprocessor``.
        init_cfg (dict, optional): mmengine initialisation config.
    """

    def __init__(self,
                 lidar_encoder: dict,
                 point_seg_head: dict,
                 data_preprocessor: Optional[dict] = None,
                 init_cfg: Optional[dict] = None) -> None:
        super().__init__(data_preprocessor=data_preprocessor,
                         init_cfg=init_cfg)
        if lidar_encoder.get('bev_output', True):
            raise ValueError('SPVCNNSegmentor: set lidar_encoder.bev_output='
                             'False (segmentation trains no BEV projection, '
                             'and DDP refuses parameters without gradient)')
        self.lidar_encoder = MODELS.build(lidar_encoder)
        self.point_seg_head = MODELS.build(
            point_seg_head,
            default_args=dict(in_channels=self.lidar_encoder.point_channels))

    def forward(self, inputs: dict, data_samples: Optional[list] = None,
                mode: str = 'tensor'):
        """mmengine's entry: ``'loss'``, ``'predict'`` or ``'tensor'``."""
        if mode == 'loss':
            return self.loss(inputs, data_samples)
        if mode == 'predict':
            return self.predict(inputs, data_samples)
        if mode == 'tensor':
            return self._forward(inputs)
        raise ValueError(f'SPVCNNSegmentor: unknown mode {mode!r}')

    def _points(self, inputs: dict) -> List[Tensor]:
        if 'points' not in inputs:
            raise ValueError('SPVCNNSegmentor needs inputs["points"]')
        return list(inputs['points'])

    def loss(self, inputs: dict, data_samples: Sequence) -> Dict[str, Tensor]:
        """``loss_point_seg`` over the labelled points inside the range.

        Args:
            inputs (dict): ``points``, per sample (P_b, C).
            data_samples (Sequence[Det3DDataSample]): With
                ``gt_pts_seg.pts_semantic_mask`` (P_b,).
        """
        points = self._points(inputs)
        labels = gather_point_labels(data_samples, points)
        out = self.lidar_encoder.encode_points(points)
        return self.point_seg_head.loss(out['point_feats'],
                                        labels[out['point_index']])

    def _forward(self, inputs: dict) -> Tensor:
        """Logits of the points inside the range, grouped by voxel (the
        encoder's order). Shape (P, num_classes)."""
        out = self.lidar_encoder.encode_points(self._points(inputs))
        return self.point_seg_head(out['point_feats'])

    def predict(self, inputs: dict, data_samples: Sequence) -> list:
        """Every point's most likely class (``ignore_index`` outside the
        encoder's range) as ``pred_pts_seg.pts_semantic_mask`` (P_b,)."""
        points = self._points(inputs)
        out = self.lidar_encoder.encode_points(points)
        labels = self.point_seg_head(out['point_feats']).argmax(1)
        flat = torch.full((sum(len(p) for p in points), ),
                          self.point_seg_head.ignore_index,
                          dtype=torch.long, device=labels.device)
        flat[out['point_index']] = labels
        for sample, pred in zip(data_samples,
                                flat.split([len(p) for p in points])):
            sample.pred_pts_seg = PointData(pts_semantic_mask=pred)
        return list(data_samples)
