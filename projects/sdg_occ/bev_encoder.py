"""BEV encoder of SDG-OCC: residual stages and a top-down FPN.

SDG-OCC follows BEVDet/FlashOcc here (Duan et al., CVPR 2025, Sec. 3.6):
a BEV map goes through residual stages at strides 2, 4 and 8, and an FPN
merges them back to the input resolution (200 x 200 on Occ3D) before the
channel-to-height head.
"""
from typing import Optional, Sequence

import torch
import torch.nn.functional as F
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import Tensor, nn


def _conv_bn_relu(in_channels: int, out_channels: int,
                  kernel_size: int = 3) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(
            in_channels,
            out_channels,
            kernel_size,
            padding=kernel_size // 2,
            bias=False), nn.BatchNorm2d(out_channels), nn.ReLU(inplace=True))


class _ResidualBlock(nn.Module):
    """Two 3x3 convs with an identity (or 1x1 projection) shortcut."""

    def __init__(self, in_channels: int, out_channels: int, stride: int):
        super().__init__()
        self.conv1 = nn.Conv2d(
            in_channels, out_channels, 3, stride, padding=1, bias=False)
        self.bn1 = nn.BatchNorm2d(out_channels)
        self.conv2 = nn.Conv2d(
            out_channels, out_channels, 3, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(out_channels)
        self.shortcut = nn.Identity()
        if stride != 1 or in_channels != out_channels:
            self.shortcut = nn.Sequential(
                nn.Conv2d(in_channels, out_channels, 1, stride, bias=False),
                nn.BatchNorm2d(out_channels))

    def forward(self, x: Tensor) -> Tensor:
        out = F.relu(self.bn1(self.conv1(x)), inplace=True)
        out = self.bn2(self.conv2(out))
        return F.relu(out + self.shortcut(x), inplace=True)


@MODELS.register_module()
class SDGBEVEncoder(BaseModule):
    """Residual BEV backbone with an FPN back to the input resolution.

    Stage i halves the resolution (strides 2, 4, 8, ... of the input) with
    ``num_blocks[i]`` residual blocks. The top-down path upsamples the
    deepest map, concatenates it with the next shallower stage and mixes
    them with a 3x3 conv, down to stride 2, then upsamples to the input
    size.

    Args:
        in_channels (int): Channels of the input BEV.
        stage_channels (Sequence[int]): Channels per stage.
            Defaults to (128, 256, 512).
        num_blocks (Sequence[int]): Residual blocks per stage.
            Defaults to (2, 2, 2).
        out_channels (int): Channels of the output BEV. Defaults to 256.
        init_cfg (dict, optional): mmengine initialisation config.
    """

    def __init__(self,
                 in_channels: int,
                 stage_channels: Sequence[int] = (128, 256, 512),
                 num_blocks: Sequence[int] = (2, 2, 2),
                 out_channels: int = 256,
                 init_cfg: Optional[dict] = None):
        super().__init__(init_cfg=init_cfg)
        if len(stage_channels) != len(num_blocks) or not stage_channels:
            raise ValueError('SDGBEVEncoder needs one num_blocks entry per '
                             f'stage, got stage_channels {stage_channels} '
                             f'and num_blocks {num_blocks}')
        if min(num_blocks) < 1:
            raise ValueError(f'num_blocks must be >= 1, got {num_blocks}')
        self.stages = nn.ModuleList()
        channels = in_channels
        for width, blocks in zip(stage_channels, num_blocks):
            layers = [_ResidualBlock(channels, width, stride=2)]
            layers += [
                _ResidualBlock(width, width, stride=1)
                for _ in range(blocks - 1)
            ]
            self.stages.append(nn.Sequential(*layers))
            channels = width
        self.merges = nn.ModuleList()
        for shallow in reversed(stage_channels[:-1]):
            self.merges.append(_conv_bn_relu(channels + shallow, shallow))
            channels = shallow
        self.out = nn.Sequential(
            _conv_bn_relu(channels, out_channels),
            nn.Conv2d(out_channels, out_channels, 1))

    def forward(self, x: Tensor) -> Tensor:
        """Encode a BEV map.

        Args:
            x (Tensor): BEV features. Shape (B, C_in, Y, X).

        Returns:
            Tensor: Encoded BEV. Shape (B, out_channels, Y, X).
        """
        if x.dim() != 4:
            raise ValueError('SDGBEVEncoder expects (B, C, Y, X), got '
                             f'{tuple(x.shape)}')
        feats = []
        out = x
        for stage in self.stages:
            out = stage(out)
            feats.append(out)
        out = feats[-1]
        for merge, shallow in zip(self.merges, reversed(feats[:-1])):
            # Upsampling to the exact shallow size handles odd sizes, where
            # a fixed factor of 2 would be off by one.
            out = F.interpolate(
                out,
                size=shallow.shape[-2:],
                mode='bilinear',
                align_corners=False)
            out = merge(torch.cat([out, shallow], dim=1))
        out = F.interpolate(
            out, size=x.shape[-2:], mode='bilinear', align_corners=False)
        return self.out(out)
