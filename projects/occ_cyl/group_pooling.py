"""Spatial group pooling: volume -> three TPV-polar planes (eqs. 8-13)."""
from typing import Tuple

from mmcv.cnn import ConvModule
from mmdet3d.registry import MODELS
from mmdet3d.utils import ConfigType, OptMultiConfig
from mmengine.model import BaseModule
from torch import Tensor, nn

# Volume axes of (B, C, R, Theta, Z) pooled away for each plane, in the
# order the planes are returned: (R, Theta), (Theta, Z), (R, Z).
PLANE_POOL_AXES = (4, 2, 3)


@MODELS.register_module()
class SpatialGroupPooling(BaseModule):
    """Compress a cylindrical volume into three planes by group pooling.

    Implements eqs. 8-13 of OccCylindrical (PointOcc's spatial group
    pooling). Along the pooled axis of length ``L`` the volume is split into
    ``M`` consecutive groups of ``L / M`` cells, each group is max-pooled,
    the ``M`` results are concatenated on channels (group-major: channel
    ``g * C + c`` holds channel ``c`` of group ``g``) and a per-plane MLP
    (two 1x1 convs) filters them to ``out_channels``. ``M = 1`` is plain
    max pooling along the axis (Table VII).

    Args:
        in_channels (int): Channels ``C`` of the volume.
        out_channels (int): Channels of each plane.
        num_groups (int): ``M``; must divide ``R``, ``Theta`` and ``Z``.
            Defaults to 8 (the paper).
        norm_cfg (dict): Normalisation of the MLP. Defaults to BN2d.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 in_channels: int,
                 out_channels: int,
                 num_groups: int = 8,
                 norm_cfg: ConfigType = dict(type='BN2d'),
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(init_cfg=init_cfg)
        if num_groups < 1:
            raise ValueError('SpatialGroupPooling: num_groups must be >= 1, '
                             f'got {num_groups}')
        self.in_channels = in_channels
        self.num_groups = num_groups
        self.mlps = nn.ModuleList([
            nn.Sequential(
                ConvModule(
                    in_channels * num_groups,
                    out_channels,
                    1,
                    norm_cfg=norm_cfg), nn.Conv2d(out_channels, out_channels,
                                                  1)) for _ in PLANE_POOL_AXES
        ])

    def group_pool(self, volume: Tensor, axis: int) -> Tensor:
        """Group max pooling along one axis, before the MLP (eqs. 8-10).

        Args:
            volume (Tensor): Shape (B, C, R, Theta, Z).
            axis (int): Pooled axis, 2 (R), 3 (Theta) or 4 (Z).

        Returns:
            Tensor: The two kept axes in order, e.g. for ``axis=4``
            Shape (B, M * C, R, Theta).
        """
        if volume.dim() != 5 or volume.shape[1] != self.in_channels:
            raise ValueError(
                'SpatialGroupPooling expects a volume (B, '
                f'{self.in_channels}, R, Theta, Z), got {tuple(volume.shape)}')
        if axis not in (2, 3, 4):
            raise ValueError(f'axis must be 2, 3 or 4, got {axis}')
        length = volume.shape[axis]
        groups = self.num_groups
        if length % groups:
            raise ValueError(f'SpatialGroupPooling: axis {axis} of length '
                             f'{length} is not divisible into {groups} groups')
        shape = list(volume.shape)
        shape[axis:axis + 1] = [groups, length // groups]
        pooled = volume.reshape(shape).amax(dim=axis + 1)
        # Move the group axis next to the channels: (B, M, C, a, b).
        pooled = pooled.movedim(axis, 1)
        b, m, c, h, w = pooled.shape
        return pooled.reshape(b, m * c, h, w)

    def forward(self, volume: Tensor) -> Tuple[Tensor, Tensor, Tensor]:
        """Compute the three TPV-polar planes (eqs. 11-13).

        Args:
            volume (Tensor): Shape (B, C, R, Theta, Z).

        Returns:
            tuple[Tensor]: Planes (R, Theta), (Theta, Z) and (R, Z):
            Shape (B, out_channels, R, Theta), (B, out_channels, Theta, Z),
            (B, out_channels, R, Z).
        """
        return tuple(
            mlp(self.group_pool(volume, axis))
            for mlp, axis in zip(self.mlps, PLANE_POOL_AXES))
