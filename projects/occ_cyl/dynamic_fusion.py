"""OccFusion-style 2D dynamic fusion of a camera and a LiDAR plane."""
from typing import Sequence

import torch
from mmcv.cnn import ConvModule
from mmdet3d.registry import MODELS
from mmdet3d.utils import ConfigType, OptMultiConfig
from mmengine.model import BaseModule
from torch import Tensor, nn

#: DynamicFusion2D's channel gates.
GATES = ('conv', 'squeeze_excite')


@MODELS.register_module()
class DynamicFusion2D(BaseModule):
    """Fuse same-sized feature planes with a learned channel attention.

    The dynamic fusion of OccFusion (Ming et al., 2024) in 2D, as used by
    OccCylindrical for each TPV-polar plane: the inputs are concatenated,
    a 3x3 conv-BN-ReLU mixes them, and a channel gate re-weights the
    channels per sample, so the network can lean on the LiDAR or the camera
    plane depending on the scene.

    Args:
        in_channels (Sequence[int]): Channels of each input plane.
        out_channels (int): Channels of the fused plane.
        norm_cfg (dict): Normalisation config. Defaults to BN2d.
        gate (str): ``'conv'``: global average pooling, a 1x1 conv C -> C
            with bias, sigmoid (this class's form before 2026-11-28).
            ``'squeeze_excite'``: OCCFusion's released ``DynamicFusion2D``,
            pooling, C -> C / 2 without bias, ReLU, C / 2 -> C without
            bias, sigmoid (1x1 convs on the pooled vector, the same as its
            Linear layers). Defaults to 'conv'.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 in_channels: Sequence[int],
                 out_channels: int,
                 norm_cfg: ConfigType = dict(type='BN2d'),
                 gate: str = 'conv',
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(init_cfg=init_cfg)
        if gate not in GATES:
            raise ValueError(f'DynamicFusion2D gate must be one of {GATES}, '
                             f'got {gate!r}')
        self.in_channels = tuple(int(c) for c in in_channels)
        self.fuse = ConvModule(
            sum(self.in_channels),
            out_channels,
            3,
            padding=1,
            norm_cfg=norm_cfg)
        if gate == 'conv':
            self.gate = nn.Sequential(
                nn.AdaptiveAvgPool2d(1),
                nn.Conv2d(out_channels, out_channels, 1), nn.Sigmoid())
        else:
            squeezed = max(out_channels // 2, 1)
            self.gate = nn.Sequential(
                nn.AdaptiveAvgPool2d(1),
                nn.Conv2d(out_channels, squeezed, 1, bias=False),
                nn.ReLU(inplace=True),
                nn.Conv2d(squeezed, out_channels, 1, bias=False),
                nn.Sigmoid())

    def forward(self, *planes: Tensor) -> Tensor:
        """Fuse the planes.

        Args:
            *planes (Tensor): One plane per input. Shape (B, C_i, H, W).

        Returns:
            Tensor: Fused plane. Shape (B, out_channels, H, W).
        """
        channels = tuple(p.shape[1] for p in planes)
        if channels != self.in_channels or \
                len({tuple(p.shape[2:]) for p in planes}) != 1:
            raise ValueError(
                f'DynamicFusion2D expects planes with channels '
                f'{self.in_channels} and one spatial size, got shapes '
                f'{[tuple(p.shape) for p in planes]}')
        fused = self.fuse(torch.cat(planes, dim=1))
        return fused * self.gate(fused)
