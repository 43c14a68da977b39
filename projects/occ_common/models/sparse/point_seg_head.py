"""Per-point semantic classifier of a sparse LiDAR encoder, with its loss.

SDG-OCC's released code trains its SPVCNN with a point segmentation loss
beside the occupancy loss (times 0.1) and pre-trains it on
nuScenes-lidarseg; neither is in the paper's text. This head classifies
the encoder's point features (:meth:`SPVCNNEncoder.encode_points`) into
the lidarseg classes for both.
"""
from typing import Dict, Optional

import torch.nn.functional as F
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import Tensor, nn


@MODELS.register_module()
class PointSegHead(BaseModule):
    """``Linear - ReLU - Linear`` point classifier and its cross-entropy.

    The release's classifier has the same form (256 -> 128 -> 17 on one
    scale's voxel features); here it reads every point's final point
    feature.

    Args:
        in_channels (int): Channels of the point features.
        num_classes (int): Classes (17: "no class" 0 and the 16 lidarseg
            classes 1..16 of ``LoadLidarSegLabels``).
        mid_channels (int): Hidden width. Defaults to 128, the release's.
        ignore_index (int): Label without supervision (``LoadLidarSegLabels``
            gives it to noise and to the merged sweeps' points).
            Defaults to 255.
        loss_weight (float): Factor of the loss. Defaults to 1.0.
        init_cfg (dict, optional): mmengine initialisation config.
    """

    def __init__(self,
                 in_channels: int,
                 num_classes: int,
                 mid_channels: int = 128,
                 ignore_index: int = 255,
                 loss_weight: float = 1.0,
                 init_cfg: Optional[dict] = None) -> None:
        super().__init__(init_cfg=init_cfg)
        if num_classes < 2:
            raise ValueError(f'PointSegHead needs num_classes >= 2, got '
                             f'{num_classes}')
        self.num_classes = num_classes
        self.ignore_index = ignore_index
        self.loss_weight = float(loss_weight)
        self.classifier = nn.Sequential(
            nn.Linear(in_channels, mid_channels), nn.ReLU(inplace=True),
            nn.Linear(mid_channels, num_classes))

    def forward(self, point_feats: Tensor) -> Tensor:
        """Logits of every point.

        Args:
            point_feats (Tensor): Shape (P, in_channels).

        Returns:
            Tensor: Shape (P, num_classes).
        """
        return self.classifier(point_feats)

    def loss(self, point_feats: Tensor, labels: Tensor) -> Dict[str, Tensor]:
        """Cross-entropy over the labelled points.

        Args:
            point_feats (Tensor): Shape (P, in_channels).
            labels (Tensor): Long, ``ignore_index`` where unlabelled.
                Shape (P,).

        Returns:
            dict[str, Tensor]: ``loss_point_seg``, the mean over the
            labelled points times ``loss_weight`` (0, with a gradient, when
            no point is labelled).
        """
        if labels.shape != point_feats.shape[:1]:
            raise ValueError(f'PointSegHead: {tuple(labels.shape)} labels '
                             f'for {point_feats.shape[0]} points')
        logits = self(point_feats)
        total = F.cross_entropy(
            logits.float(), labels.long(), ignore_index=self.ignore_index,
            reduction='sum')
        count = (labels != self.ignore_index).sum().clamp(min=1)
        return dict(loss_point_seg=self.loss_weight * total / count)


def gather_point_labels(data_samples, points) -> Tensor:
    """The samples' point labels, concatenated as ``torch.cat(points)``.

    Args:
        data_samples (Sequence[Det3DDataSample]): With
            ``gt_pts_seg.pts_semantic_mask`` (P_b,) (``PackOccInputs`` of
            ``LoadLidarSegLabels``' labels).
        points (Sequence[Tensor]): The samples' points, (P_b, C) each.

    Returns:
        Tensor: Long labels on the points' device. Shape (sum P_b,).

    Raises:
        ValueError: A sample without labels or with another count, naming
            its token.
    """
    import torch
    labels = []
    for sample, pts in zip(data_samples, points):
        token = sample.metainfo.get('token', '?')
        seg = getattr(sample, 'gt_pts_seg', None)
        mask = None if seg is None else seg.get('pts_semantic_mask')
        if mask is None:
            raise ValueError(
                f'sample {token} has no point labels: the point segmentation '
                'loss needs nuScenes-lidarseg (LoadLidarSegLabels in the '
                'pipeline, docs/dataset_prepare.md); set the model\'s '
                'point_seg_head=None to train without it')
        if len(mask) != len(pts):
            raise ValueError(f'sample {token}: {len(mask)} point labels for '
                             f'{len(pts)} points')
        labels.append(torch.as_tensor(mask, device=pts.device).long())
    return torch.cat(labels) if labels else torch.zeros(0, dtype=torch.long)
