"""Spatial group pooling: occupied voxels -> three TPV-polar planes (eqs.
8-13)."""
from typing import Sequence, Tuple

from mmcv.cnn import ConvModule
from mmdet3d.registry import MODELS
from mmdet3d.utils import ConfigType, OptMultiConfig
from mmengine.model import BaseModule
from torch import Tensor, nn

from projects.occ_common.models.layers import cell_max
from projects.occ_common.models.layers.checkpointing import checkpoint_if_grad

#: For the planes in the order they are returned, (R, Theta), (Theta, Z)
#: and (R, Z): the pooled cylinder axis and the two kept axes, as columns
#: of the ``(b, i, j, k)`` voxel coordinates (1 = R, 2 = Theta, 3 = Z).
PLANE_POOL_AXES = ((3, (1, 2)), (1, (2, 3)), (2, (1, 3)))


@MODELS.register_module()
class SpatialGroupPooling(BaseModule):
    """Compress the occupied voxels of a cylinder into three planes.

    Implements eqs. 8-13 of OccCylindrical (PointOcc's spatial group
    pooling). Along the pooled axis of length ``L`` the cylinder is split
    into ``M`` consecutive groups of ``L / M`` cells, each group is
    max-pooled, the ``M`` results are concatenated on channels
    (group-major: channel ``g * C + c`` holds channel ``c`` of group ``g``)
    and a per-plane MLP (two 1x1 convs) filters them to ``out_channels``.
    ``M = 1`` is plain max pooling along the axis (Table VII).

    The input is the list of occupied voxels (their pooled features and
    coordinates), never a dense ``(C, R, Theta, Z)`` volume: a group's
    maximum is taken over its occupied voxels only, as eqs. 8-13 pool over
    the points. Camera features are signed (the DepthNet context has no
    final activation), so a zero-filled empty voxel would otherwise win the
    maximum of a group of negative features: ``[-0.7, -0.3, empty, empty]``
    pools to -0.3, not 0. A group without any occupied voxel is 0. The
    gradient of a pooled value reaches the voxel that holds the maximum;
    voxels of one group that tie exactly share it equally (torch's ``amax``
    rule; :func:`~projects.occ_common.models.layers.cell_max`).

    Args:
        in_channels (int): Channels ``C`` of the voxel features.
        out_channels (int): Channels of each plane.
        num_groups (int): ``M``; must divide ``R``, ``Theta`` and ``Z``.
            Defaults to 8 (the paper).
        norm_cfg (dict, optional): Normalisation of the MLP's first layer;
            None: none, the layer has a bias (PointOcc's Linear - ReLU -
            Linear). Defaults to BN2d.
        with_cp (bool): In training, keep only the voxel features for the
            backward and recompute each plane's pooling and MLP there
            (exact, the MLP's BatchNorm statistics update once). At the
            paper's 480 x 368 x 32 cylinder, M = 8 and 64 channels a pooled
            (R, Theta) plane is 345 MiB and the in-place pooling keeps it
            twice. Defaults to False.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 in_channels: int,
                 out_channels: int,
                 num_groups: int = 8,
                 norm_cfg: ConfigType = dict(type='BN2d'),
                 with_cp: bool = False,
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(init_cfg=init_cfg)
        self.with_cp = with_cp
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

    def _check(self, feats: Tensor, coords: Tensor,
               shape: Sequence[int]) -> None:
        if feats.dim() != 2 or feats.shape[1] != self.in_channels or \
                coords.shape != (feats.shape[0], 4):
            raise ValueError(
                'SpatialGroupPooling expects voxel features (U, '
                f'{self.in_channels}) and coordinates (U, 4), got '
                f'{tuple(feats.shape)} and {tuple(coords.shape)}')
        for axis, length in zip('R Theta Z'.split(), shape):
            if length % self.num_groups:
                raise ValueError(
                    f'SpatialGroupPooling: the {axis} axis of length '
                    f'{length} is not divisible into {self.num_groups} '
                    'groups')

    def group_pool(self, feats: Tensor, coords: Tensor, shape: Sequence[int],
                   batch_size: int, plane: int) -> Tensor:
        """Group max pooling into one plane, before the MLP (eqs. 8-10).

        Args:
            feats (Tensor): Features of the occupied voxels. Shape (U, C).
            coords (Tensor): Their ``(b, i, j, k)`` coordinates, int64.
                Shape (U, 4).
            shape (Sequence[int]): Cells ``(R, Theta, Z)`` of the cylinder.
            batch_size (int): Number of samples ``B``.
            plane (int): 0 (pool Z), 1 (pool R) or 2 (pool Theta).

        Returns:
            Tensor: The two kept axes in order, e.g. for ``plane=0``
            Shape (B, M * C, R, Theta), 0 where a group has no occupied
            voxel.
        """
        self._check(feats, coords, shape)
        if plane not in (0, 1, 2):
            raise ValueError(f'plane must be 0, 1 or 2, got {plane}')
        pooled, (kept_a, kept_b) = PLANE_POOL_AXES[plane]
        groups = self.num_groups
        size_a, size_b = shape[kept_a - 1], shape[kept_b - 1]
        group = coords[:, pooled] // (shape[pooled - 1] // groups)
        cell = ((coords[:, 0] * size_a + coords[:, kept_a]) * size_b +
                coords[:, kept_b]) * groups + group
        channels = feats.shape[1]
        # Only occupied voxels compete; a cell no voxel reaches is 0.
        # torch's index_reduce amax values and gradient, with a backward
        # ~3 GB smaller at the paper's cylinder.
        out = cell_max(feats, cell, batch_size * size_a * size_b * groups)
        # (B, a, b, M * C) viewed as (B, M * C, a, b): channels-last strides,
        # no copy of the largest tensor of the fusion.
        return out.view(batch_size, size_a, size_b,
                        groups * channels).permute(0, 3, 1, 2)

    def forward(self, feats: Tensor, coords: Tensor, shape: Sequence[int],
                batch_size: int) -> Tuple[Tensor, Tensor, Tensor]:
        """Compute the three TPV-polar planes (eqs. 11-13).

        Args:
            feats (Tensor): Features of the occupied voxels. Shape (U, C).
            coords (Tensor): Their ``(b, i, j, k)`` coordinates, int64.
                Shape (U, 4).
            shape (Sequence[int]): Cells ``(R, Theta, Z)`` of the cylinder.
            batch_size (int): Number of samples ``B``.

        Returns:
            tuple[Tensor]: Planes (R, Theta), (Theta, Z) and (R, Z):
            Shape (B, out_channels, R, Theta), (B, out_channels, Theta, Z),
            (B, out_channels, R, Z).
        """
        return tuple(
            checkpoint_if_grad(
                self.with_cp, self._plane, feats, coords, shape, batch_size,
                plane, module=mlp) for plane, mlp in enumerate(self.mlps))

    def _plane(self, feats: Tensor, coords: Tensor, shape: Sequence[int],
               batch_size: int, plane: int) -> Tensor:
        """One plane: :meth:`group_pool`, then its MLP.

        Returns:
            Tensor: E.g. for ``plane=0`` Shape (B, out_channels, R, Theta).
        """
        return self.mlps[plane](
            self.group_pool(feats, coords, shape, batch_size, plane))
