"""TPV-Polar-Fusion: both point clouds to fused TPV-polar planes.

Implements step 5 of OccCylindrical: eqs. 6-7 (cylindrical partition and
per-voxel max pooling), eqs. 8-13 (spatial group pooling) and the 2D dynamic
fusion of each camera plane with its LiDAR plane.
"""
from typing import List, Optional, Tuple

import torch
from mmdet3d.registry import MODELS
from mmdet3d.utils import ConfigType, OptMultiConfig
from mmengine.model import BaseModule
from torch import Tensor, nn

from projects.occ_common.models.layers import cartesian_to_cylindrical
from projects.occ_common.utils.device_path import chunk_items
from .cylindrical import CylinderGrid
from .dynamic_fusion import DynamicFusion2D
from .group_pooling import SpatialGroupPooling
from .lift_pool import lift_max_pool, voxel_max_pool

#: Points per chunk of the fused lift on the CPU (its cache).
CPU_LIFT_CHUNK = 16384


@MODELS.register_module()
class TPVPolarFusion(BaseModule):
    """Fuse the pseudo-3D (camera) and LiDAR point clouds into TPV planes.

    The camera cloud is given in factorised form (depth distribution,
    context and each bin's 3D point) so that the lift and the voxel max
    pooling run as one fused operation (:func:`lift_max_pool`). Both clouds
    are pooled into their *occupied* voxels only (the indices are compacted
    with :meth:`CylinderGrid.occupied`), and the group pooling reads those
    rows straight into the planes: no dense ``(C, R, Theta, Z)`` volume is
    built (1.4 GB per modality at 480 x 368 x 32 cells and 64 channels),
    and empty voxels never take part in a group's maximum. Points outside
    the cylinder are clamped into its border voxels or dropped, as the
    cylinder says (:class:`CylinderGrid`).

    With a single modality (``with_camera`` or ``with_lidar`` False) the
    planes of that modality are returned without fusion.

    Args:
        cylinder (CylinderGrid): The cylindrical volume, the one
            :class:`OccCylindrical` builds and shares with the head.
        cam_channels (int): Channels of the pseudo points (``V_context``).
        lidar_channels (int): Channels of the LiDAR point features.
        plane_channels (int): Channels of every output plane.
        num_groups (int): ``M`` of the group pooling. Defaults to 8.
        with_camera (bool): Use the camera cloud. Defaults to True.
        with_lidar (bool): Use the LiDAR cloud. Defaults to True.
        fused_lift (bool): Fused lift-pool (True) or the naive reference.
            Defaults to True.
        lift_chunk_size (int, optional): Points per chunk of the fused
            lift. Defaults to None: 16,384 on the CPU (its cache), on a GPU
            as many as a quarter of the free memory holds at 16 bytes per
            point-channel (one or two chunks at paper size instead of
            ~100; :func:`~projects.occ_common.utils.device_path.chunk_items`).
        norm_cfg (dict): Normalisation of the MLPs and fusion.
            Defaults to BN2d.
        fusion_gate (str): The channel gate of the plane fusions
            (:class:`DynamicFusion2D`'s ``gate``). Defaults to 'conv'.
        group_mlp_norm (bool): Normalise the first layer of the group
            pooling MLPs with ``norm_cfg`` (True, the default) or not, as
            PointOcc's ``Linear - ReLU - Linear`` (False).
        with_cp (bool): Recompute the group pooling in the backward
            (:class:`SpatialGroupPooling`'s ``with_cp``). Defaults to False.
        padded_voxels (bool, optional): Pool each cloud into a list of
            one row per point instead of one per occupied voxel
            (:meth:`CylinderGrid.occupied_padded`): no size depends on the
            data, so ``torch.compile`` traces the pooling without a graph
            break, for ~3x the camera's pooled rows at paper size (1.74 M
            pseudo points, ~0.56 M occupied voxels). The planes are the
            same. Defaults to None: padded while being compiled, compacted
            otherwise.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 cylinder: CylinderGrid,
                 cam_channels: int,
                 lidar_channels: int,
                 plane_channels: int,
                 num_groups: int = 8,
                 with_camera: bool = True,
                 with_lidar: bool = True,
                 fused_lift: bool = True,
                 lift_chunk_size: Optional[int] = None,
                 norm_cfg: ConfigType = dict(type='BN2d'),
                 fusion_gate: str = 'conv',
                 group_mlp_norm: bool = True,
                 with_cp: bool = False,
                 padded_voxels: Optional[bool] = None,
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(init_cfg=init_cfg)
        self.padded_voxels = padded_voxels
        if not (with_camera or with_lidar):
            raise ValueError('TPVPolarFusion needs at least one modality')
        self.cylinder = cylinder
        for size in cylinder.shape:
            if size % num_groups:
                raise ValueError(
                    f'TPVPolarFusion: num_groups={num_groups} must divide '
                    f'every axis of the cylinder {cylinder.shape}')
        self.with_camera = with_camera
        self.with_lidar = with_lidar
        self.fused_lift = fused_lift
        self.lift_chunk_size = lift_chunk_size
        self.plane_channels = plane_channels
        pool_norm = norm_cfg if group_mlp_norm else None
        if with_camera:
            self.cam_pool = SpatialGroupPooling(cam_channels, plane_channels,
                                                num_groups, pool_norm, with_cp)
        if with_lidar:
            self.lidar_pool = SpatialGroupPooling(lidar_channels,
                                                  plane_channels, num_groups,
                                                  pool_norm, with_cp)
        if with_camera and with_lidar:
            self.fusions = nn.ModuleList([
                DynamicFusion2D((plane_channels, plane_channels),
                                plane_channels, norm_cfg, fusion_gate)
                for _ in range(3)
            ])

    def camera_voxels(self, depth: Tensor, context: Tensor,
                      cam_points: Tensor) -> Tuple[Tensor, Tensor]:
        """Lift the pseudo points and max-pool them per voxel (eqs. 6-7).

        Args:
            depth (Tensor): ``V_depth``. Shape (B*N, D, h, w).
            context (Tensor): ``V_context``. Shape (B*N, C, h, w).
            cam_points (Tensor): Working-frame point of every bin.
                Shape (B, N, D, h, w, 3).

        Returns:
            tuple[Tensor, Tensor]: The pooled features of the occupied
            voxels, Shape (U, C), and their flat indices (sample included,
            :meth:`CylinderGrid.flat_index`), sorted, Shape (U,); with
            ``padded_voxels``, padding rows after them up to one row per
            pseudo point (see the comment below).
        """
        batch_size, num_cams = cam_points.shape[:2]
        if depth.shape[0] != batch_size * num_cams or \
                tuple(depth.shape[1:]) != tuple(cam_points.shape[2:5]):
            raise ValueError(f'TPVPolarFusion: depth {tuple(depth.shape)} '
                             'does not match cam_points '
                             f'{tuple(cam_points.shape)}')
        batch_idx = torch.arange(
            batch_size, device=depth.device).view(-1, 1, 1, 1, 1)
        flat = self.cylinder.flat_index(
            cartesian_to_cylindrical(cam_points), batch_idx)
        voxels, rows, filled = self._occupied(flat)
        pooled = lift_max_pool(
            depth,
            context,
            rows.flatten(0, 1),
            voxels.numel(),
            fused=self.fused_lift,
            chunk_size=self.lift_chunk_size or chunk_items(
                context, 16 * context.shape[1], CPU_LIFT_CHUNK))
        return self._park_padding(pooled, voxels, filled)

    def _occupied(self, flat: Tensor
                  ) -> Tuple[Tensor, Tensor, Optional[Tensor]]:
        """The occupied voxels and each point's row
        (:meth:`CylinderGrid.occupied`), or with ``padded_voxels`` one row
        per point and which rows are filled
        (:meth:`CylinderGrid.occupied_padded`); else None."""
        padded = self.padded_voxels
        if padded is None:
            padded = torch.compiler.is_compiling()
        if padded:
            return self.cylinder.occupied_padded(flat)
        return (*self.cylinder.occupied(flat), None)

    @staticmethod
    def _park_padding(pooled: Tensor, voxels: Tensor,
                      filled: Optional[Tensor]) -> Tuple[Tensor, Tensor]:
        """Padding rows that change no plane.

        They join the group of the first (smallest) occupied voxel at
        -inf, which never wins a maximum (nor takes a share of its
        gradient); with no voxel occupied they are 0s in voxel 0, which
        is then 0 as an empty group is.
        """
        if filled is None or filled.numel() == 0:
            return pooled, voxels
        any_voxel = filled[0]
        voxels = torch.where(filled, voxels,
                             torch.where(any_voxel, voxels[0], 0))
        pooled = pooled.masked_fill(
            ~filled[:, None],
            torch.where(any_voxel, float('-inf'), 0.0).to(pooled.dtype))
        return pooled, voxels

    def lidar_voxels(self, feats: List[Tensor],
                     xyz: List[Tensor]) -> Tuple[Tensor, Tensor]:
        """Max-pool the LiDAR point features per voxel (eqs. 6-7).

        Args:
            feats (list[Tensor]): Per sample. Shape (P_i, C).
            xyz (list[Tensor]): Per sample, working-frame points.
                Shape (P_i, 3).

        Returns:
            tuple[Tensor, Tensor]: As :meth:`camera_voxels`.
        """
        if len(feats) != len(xyz):
            raise ValueError(f'TPVPolarFusion: {len(feats)} feature sets '
                             f'for {len(xyz)} point clouds')
        index = [
            self.cylinder.flat_index(cartesian_to_cylindrical(p[:, :3]), i)
            for i, p in enumerate(xyz)
        ]
        voxels, rows, filled = self._occupied(torch.cat(index, dim=0))
        pooled = voxel_max_pool(
            torch.cat(feats, dim=0), rows, voxels.numel())
        return self._park_padding(pooled, voxels, filled)

    def _planes(self, pool: SpatialGroupPooling, pooled: Tensor,
                voxels: Tensor, batch_size: int) -> Tuple[Tensor, ...]:
        return pool(pooled, self.cylinder.unravel(voxels),
                    self.cylinder.shape, batch_size)

    def forward(self,
                depth: Tensor = None,
                context: Tensor = None,
                cam_points: Tensor = None,
                lidar_feats: List[Tensor] = None,
                lidar_xyz: List[Tensor] = None) -> Tuple[Tensor, ...]:
        """Build the fused planes.

        Args:
            depth (Tensor, optional): ``V_depth``. Shape (B*N, D, h, w).
            context (Tensor, optional): ``V_context``.
                Shape (B*N, C, h, w).
            cam_points (Tensor, optional): Bins' working-frame points.
                Shape (B, N, D, h, w, 3).
            lidar_feats (list[Tensor], optional): Per sample.
                Shape (P_i, C_lidar).
            lidar_xyz (list[Tensor], optional): Per sample.
                Shape (P_i, 3).

        Returns:
            tuple[Tensor]: Planes (R, Theta), (Theta, Z), (R, Z):
            Shape (B, C, R, Theta), (B, C, Theta, Z), (B, C, R, Z).
        """
        planes = []
        if self.with_camera:
            if depth is None or context is None or cam_points is None:
                raise ValueError('TPVPolarFusion: with_camera needs depth, '
                                 'context and cam_points')
            planes.append(
                self._planes(self.cam_pool,
                             *self.camera_voxels(depth, context, cam_points),
                             cam_points.shape[0]))
        if self.with_lidar:
            if lidar_feats is None or lidar_xyz is None:
                raise ValueError('TPVPolarFusion: with_lidar needs '
                                 'lidar_feats and lidar_xyz')
            planes.append(
                self._planes(self.lidar_pool,
                             *self.lidar_voxels(lidar_feats, lidar_xyz),
                             len(lidar_feats)))
        if len(planes) == 1:
            return planes[0]
        return tuple(
            fusion(cam, lidar)
            for fusion, cam, lidar in zip(self.fusions, *planes))
