"""Cylindrical-to-Cartesian multi-scale occupancy head (eqs. 17-18)."""
from typing import Dict, List, Optional, Sequence, Tuple

import torch
import torch.nn.functional as F
from mmdet3d.registry import MODELS
from mmdet3d.utils import OptConfigType, OptMultiConfig
from mmengine.model import BaseModule
from torch import Tensor, nn

from projects.occ_common.models.layers import cartesian_to_cylindrical
from projects.occ_common.models.layers.checkpointing import checkpoint_if_grad
from .cylindrical import CylinderGrid

# (height axis, width axis) of each plane as cylinder axes 0 = r,
# 1 = theta, 2 = z, in the order TPVPolarFusion returns the planes.
PLANE_AXES = ((0, 1), (1, 2), (0, 2))


def sample_plane(plane: Tensor, coords: Tensor, wrap_h: bool,
                 wrap_w: bool) -> Tensor:
    """Bilinearly sample a plane at normalised coordinates.

    A wrapped axis (the full-circle azimuth) is padded circularly by one
    cell so that samples between the last and the first cell interpolate
    across the seam at ``theta = +-pi``. Within half a cell of a non-wrapped
    edge (``r = 0``, ``r_max``, ``z_min``, ``z_max``) the edge value is
    repeated rather than faded to zero.

    Args:
        plane (Tensor): Shape (B, C, H, W).
        coords (Tensor): ``(h, w)`` in ``[-1, 1]`` (``align_corners=False``
            convention). Shape (P, 2), shared by the batch.
        wrap_h (bool): The height axis is periodic.
        wrap_w (bool): The width axis is periodic.

    Returns:
        Tensor: Samples. Shape (B, C, P).
    """
    coords = coords.to(plane.dtype)
    h_coord, w_coord = coords.unbind(-1)
    if wrap_h:
        size = plane.shape[2]
        plane = torch.cat([plane[:, :, -1:], plane, plane[:, :, :1]], dim=2)
        h_coord = ((h_coord + 1) * size + 2) / (size + 2) - 1
    if wrap_w:
        size = plane.shape[3]
        plane = torch.cat([plane[..., -1:], plane, plane[..., :1]], dim=3)
        w_coord = ((w_coord + 1) * size + 2) / (size + 2) - 1
    grid = torch.stack([w_coord, h_coord], dim=-1)
    grid = grid.view(1, 1, -1, 2).expand(plane.shape[0], -1, -1, -1)
    out = F.grid_sample(
        plane,
        grid,
        mode='bilinear',
        padding_mode='border',
        align_corners=False)
    return out[:, :, 0]


def voxel_centres(pc_range: Sequence[float], shape: Sequence[int]) -> Tensor:
    """Cartesian centres of a voxel grid, flattened in (x, y, z) order.

    Args:
        pc_range (Sequence[float]): ``(x0, y0, z0, x1, y1, z1)``.
        shape (Sequence[int]): ``(X, Y, Z)``.

    Returns:
        Tensor: Centres. Shape (X * Y * Z, 3).
    """
    axes = [
        pc_range[i] + (torch.arange(shape[i], dtype=torch.float64) + 0.5) *
        (pc_range[i + 3] - pc_range[i]) / shape[i] for i in range(3)
    ]
    grid = torch.meshgrid(*axes, indexing='ij')
    return torch.stack(grid, dim=-1).reshape(-1, 3)


@MODELS.register_module()
class CylindricalOccHead(BaseModule):
    """Classify Cartesian voxels from the cylindrical TPV planes.

    For every scale ``l`` the centres of its Cartesian grid (``X / 2^l``
    etc.) are converted to ``(r, theta, z)``; each of the three planes of
    that scale is sampled bilinearly at the centre's two coordinates, the
    three samples are summed (eq. 17, TPVFormer's aggregation) and an MLP
    classifies them. Either the cylinder covers every voxel of the grid
    (checked at construction) or it clamps: then a voxel beyond its radius
    or height is sampled at the border cells (``grid_sample``'s border
    padding), as PointOcc clamps its voxel centres into the cylinder, and as
    the cylinder clamps the points.

    Args:
        in_channels (int): Channels of the encoded planes.
        cylinder (CylinderGrid): The cylinder of the planes, the one
            :class:`OccCylindrical` builds and shares with the fusion.
        point_cloud_range (Sequence[float]): Cartesian grid range
            ``(x0, y0, z0, x1, y1, z1)``.
        voxel_size (Sequence[float]): Voxel edge per axis of the finest
            scale; scale ``l`` has ``occ_shape // 2^l`` voxels, with
            ``occ_shape = (X, Y, Z)`` the range over the voxel size.
        hidden_channels (int): Width of the classifier MLP.
        num_scales (int): Output scales, finest first. Defaults to 4
            (200x200x16 down to 25x25x2, eq. 18).
        num_classes (int): Number of classes, empty included. Defaults to
            17 (SurroundOcc-nuScenes).
        loss_occ (dict, optional): Config of the multi-scale occupancy loss
            (``MultiScaleOccupancyLoss``); it gets ``num_scales``,
            ``empty_index`` and ``ignore_index`` from here. Required by
            :meth:`loss`.
        empty_index (int): Label of empty space. Defaults to 0.
        ignore_index (int): Label of unsupervised voxels. Defaults to 255.
        with_cp (bool): In training, keep only each scale's logits for the
            backward and recompute the plane samples and the MLP from the
            planes there (``torch.utils.checkpoint``; the recomputation is
            deterministic, so values and gradients are unchanged). At the
            paper's 200 x 200 x 16 grid it saves ~1 GiB. Defaults to False.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 in_channels: int,
                 cylinder: CylinderGrid,
                 point_cloud_range: Sequence[float],
                 voxel_size: Sequence[float],
                 hidden_channels: int,
                 num_scales: int = 4,
                 num_classes: int = 17,
                 loss_occ: OptConfigType = None,
                 empty_index: int = 0,
                 ignore_index: int = 255,
                 with_cp: bool = False,
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(init_cfg=init_cfg)
        self.with_cp = with_cp
        if not (cylinder.covers_box(point_cloud_range) or cylinder.clamp):
            raise ValueError(
                f'CylindricalOccHead: the cylinder {cylinder} does not '
                'cover the occupancy range '
                f'{tuple(point_cloud_range)}; its radius must reach the '
                'corners and its azimuth the full circle, or it must '
                'clamp (then voxels outside take the border cells)')
        self.cylinder = cylinder
        self.num_classes = num_classes
        occ_shape = [
            round((point_cloud_range[i + 3] - point_cloud_range[i]) /
                  voxel_size[i]) for i in range(3)
        ]
        self.scale_shapes = [
            tuple(s // 2**level for s in occ_shape)
            for level in range(num_scales)
        ]
        self.wrap = cylinder.full_circle
        for level, shape in enumerate(self.scale_shapes):
            cyl = cartesian_to_cylindrical(
                voxel_centres(point_cloud_range, shape))
            norm = cylinder.normalize(cyl).float()
            self.register_buffer(f'centres_{level}', norm, persistent=False)
        self.classifiers = nn.ModuleList([
            nn.Sequential(
                nn.Linear(in_channels, hidden_channels), nn.Softplus(),
                nn.Linear(hidden_channels, num_classes))
            for _ in self.scale_shapes
        ])
        self.loss_occ = MODELS.build(
            loss_occ,
            default_args=dict(
                num_scales=num_scales,
                empty_index=empty_index,
                ignore_index=ignore_index)) if loss_occ else None

    def forward(self, mlvl_planes: Sequence[Tuple[Tensor, Tensor, Tensor]]
                ) -> List[Tensor]:
        """Predict logits at every scale.

        Args:
            mlvl_planes (Sequence[tuple[Tensor]]): Per scale (finest
                first), the (R, Theta), (Theta, Z), (R, Z) planes, each
                Shape (B, C, H, W).

        Returns:
            list[Tensor]: Logits per scale, finest first.
            Shape (B, num_classes, X_l, Y_l, Z_l).
        """
        if len(mlvl_planes) != len(self.scale_shapes):
            raise ValueError(
                f'CylindricalOccHead: {len(mlvl_planes)} plane scales for '
                f'{len(self.scale_shapes)} output scales')
        logits = []
        for level, planes in enumerate(mlvl_planes):
            logits.append(
                checkpoint_if_grad(self.with_cp, self._scale_logits, level,
                                   *planes))
        return logits

    def _scale_logits(self, level: int, *planes: Tensor) -> Tensor:
        """Eq. 17 at one scale: sample the three planes, sum, classify.

        Returns:
            Tensor: Shape (B, num_classes, X_l, Y_l, Z_l).
        """
        centres = getattr(self, f'centres_{level}')
        feats = 0
        for plane, (ax_h, ax_w) in zip(planes, PLANE_AXES):
            feats = feats + sample_plane(plane, centres[:, [ax_h, ax_w]],
                                         self.wrap and ax_h == 1,
                                         self.wrap and ax_w == 1)
        out = self.classifiers[level](feats.transpose(1, 2))
        return out.transpose(1, 2).reshape(out.shape[0], self.num_classes,
                                           *self.scale_shapes[level])

    def loss(self, mlvl_logits: List[Tensor],
             gt_occ: Tensor) -> Dict[str, Tensor]:
        """Multi-scale occupancy loss (eq. 18).

        Args:
            mlvl_logits (list[Tensor]): From :meth:`forward`.
            gt_occ (Tensor): Finest-scale labels. Shape (B, X, Y, Z).

        Returns:
            dict[str, Tensor]: Loss terms, e.g. ``loss_focal_s0``.
        """
        if self.loss_occ is None:
            raise ValueError('CylindricalOccHead.loss needs loss_occ')
        if tuple(gt_occ.shape[1:]) != self.scale_shapes[0]:
            raise ValueError(f'CylindricalOccHead: gt_occ of shape '
                             f'{tuple(gt_occ.shape)} does not match the '
                             f'finest grid {self.scale_shapes[0]}')
        return self.loss_occ(mlvl_logits, gt_occ)

    def predict(self, mlvl_logits: List[Tensor]) -> Tensor:
        """Finest-scale class of every voxel.

        Args:
            mlvl_logits (list[Tensor]): From :meth:`forward`.

        Returns:
            Tensor: int64 labels. Shape (B, X, Y, Z).
        """
        return mlvl_logits[0].argmax(dim=1)

    def extra_repr(self) -> Optional[str]:
        """str: The cylinder and the output scales, for ``print(model)``."""
        return (f'cylinder={self.cylinder}, '
                f'scale_shapes={self.scale_shapes}')
