"""Multi-view image branch: backbone + FPN fused to one feature map."""
import math
from typing import Sequence, Tuple

import torch
import torch.nn.functional as F
from mmcv.cnn import ConvModule
from mmdet3d.registry import MODELS
from mmdet3d.utils import ConfigType, OptMultiConfig
from mmengine.model import BaseModule
from torch import Tensor

from projects.occ_common.models.layers.checkpointing import checkpoint_if_grad


@MODELS.register_module()
class MultiViewImageEncoder(BaseModule):
    """Encode every camera image into one feature map ``V`` (step 1).

    OccCylindrical uses ``mmdet.ResNet`` (depth 50) and ``mmdet.FPN`` and
    fuses the pyramid into a single map at 1/16 of the input. Every FPN
    level is resized (bilinear) to the 1/16 grid, the levels are
    concatenated and a 3x3 conv mixes them, so coarse context and fine
    detail both reach ``V``.

    Pretrained weights reach the backbone through the detector's
    ``pretrained`` entry (:mod:`projects.occ_common.models.pretrained`,
    which checks them key by key), not through ``init_cfg``; the tests run
    from random initialisation.

    Args:
        backbone (dict): Backbone config, e.g. ``mmdet.ResNet``.
        neck (dict): Neck config, e.g. ``mmdet.FPN``.
        neck_channels (int): Channels of every neck level.
        num_levels (int): Number of neck levels fused.
        out_channels (int): Channels of ``V``.
        out_stride (int): Stride of ``V`` w.r.t. the input. Defaults to 16.
        norm_cfg (dict): Normalisation of the fusion conv. Defaults to BN.
        with_cp (bool): In training, keep only the backbone's outputs and
            ``V``'s input for the backward and recompute the neck and the
            resizing there (``torch.utils.checkpoint``; exact, as the neck
            is deterministic and has no running statistics). At 6 x 928 x
            1600 the 1/4 FPN level alone holds ~0.5 GiB per saved map.
            Defaults to False.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 backbone: ConfigType,
                 neck: ConfigType,
                 neck_channels: int,
                 num_levels: int,
                 out_channels: int,
                 out_stride: int = 16,
                 norm_cfg: ConfigType = dict(type='BN'),
                 with_cp: bool = False,
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(init_cfg=init_cfg)
        self.with_cp = with_cp
        self.backbone = MODELS.build(backbone)
        self.neck = MODELS.build(neck)
        self.num_levels = num_levels
        self.out_stride = out_stride
        self.out_channels = out_channels
        self.fuse = ConvModule(
            neck_channels * num_levels,
            out_channels,
            3,
            padding=1,
            norm_cfg=norm_cfg)

    def feature_shape(self, input_shape: Sequence[int]) -> tuple:
        """``(h, w)`` of ``V`` for a padded input ``(H, W)``."""
        return tuple(math.ceil(s / self.out_stride) for s in input_shape)

    def forward(self, imgs: Tensor) -> Tensor:
        """Encode the images.

        Args:
            imgs (Tensor): Normalised images. Shape (B, N, 3, H, W).

        Returns:
            Tensor: ``V``. Shape (B*N, out_channels, H / 16, W / 16).
        """
        if imgs.dim() != 5:
            raise ValueError('MultiViewImageEncoder expects images '
                             f'(B, N, 3, H, W), got {tuple(imgs.shape)}')
        stages = self.backbone(imgs.flatten(0, 1))
        size = self.feature_shape(imgs.shape[-2:])
        return self.fuse(
            checkpoint_if_grad(self.with_cp, self._neck_levels, size,
                               *stages))

    def _neck_levels(self, size: Tuple[int, int], *stages: Tensor) -> Tensor:
        """The neck's levels resized to ``size`` and concatenated.

        Returns:
            Tensor: Shape (B*N, neck_channels * num_levels, *size).
        """
        feats = self.neck(stages)
        if len(feats) != self.num_levels:
            raise ValueError(f'MultiViewImageEncoder: the neck gave '
                             f'{len(feats)} levels, num_levels is '
                             f'{self.num_levels}')
        feats = [
            f if tuple(f.shape[-2:]) == size else F.interpolate(
                f, size=size, mode='bilinear', align_corners=False)
            for f in feats
        ]
        return torch.cat(feats, dim=1)
