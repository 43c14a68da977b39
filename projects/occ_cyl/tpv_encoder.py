"""Shared Swin + FPN encoder-decoder over the three TPV-polar planes."""
import math
from typing import List, Sequence, Tuple

from mmdet3d.registry import MODELS
from mmdet3d.utils import ConfigType, OptMultiConfig
from mmengine.model import BaseModule
from torch import Tensor


@MODELS.register_module()
class TPVPlaneEncoder(BaseModule):
    """Encode each TPV-polar plane with one shared backbone and neck.

    Implements eqs. 14-16 of OccCylindrical: the same 2D backbone
    (``mmdet.SwinTransformer``) and the same ``mmdet.FPN`` process the
    (R, Theta), (Theta, Z) and (R, Z) planes, giving multi-scale features
    for each. The planes differ in size, so they pass through the shared
    weights one after the other.

    Every level must cover exactly the plane: mmdet's Swin pads a map whose
    size is not a multiple of a stage's stride at the bottom / right, and
    the head samples every level with the same normalised coordinates, so
    a padded level would be shifted (for a 360-cell azimuth, level 3 of a
    stride-16 Swin has 23 cells covering 368, and its last cell sits 8
    azimuth cells off). A plane side must therefore be a multiple of the
    coarsest level's stride (:meth:`check_plane_shape`); the detector checks
    its cylinder at construction and :meth:`forward` checks every level.

    Args:
        backbone (dict): Backbone config; its ``in_channels`` must equal the
            plane channels. Its ``strides`` (mmdet's Swin: the patch
            embedding's, then each patch merging's) and ``out_indices``
            give the levels' strides.
        neck (dict): Neck config producing ``num_outs`` levels.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 backbone: ConfigType,
                 neck: ConfigType,
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(init_cfg=init_cfg)
        strides = backbone.get('strides')
        out_indices = backbone.get('out_indices')
        if strides is None or out_indices is None:
            raise ValueError('TPVPlaneEncoder: the backbone config must give '
                             'strides and out_indices (the level strides), '
                             f'got {backbone}')
        #: Stride of every backbone output w.r.t. the plane.
        self.level_strides = tuple(
            math.prod(strides[:i + 1]) for i in out_indices)
        self.backbone = MODELS.build(backbone)
        self.neck = MODELS.build(neck)

    def check_plane_shape(self, shape: Sequence[int], name: str) -> None:
        """Refuse a plane whose sides some level would pad.

        Args:
            shape (Sequence[int]): ``(H, W)`` of the plane.
            name (str): The plane, for the message, e.g. ``'(R, Theta)'``.

        Raises:
            ValueError: Naming the plane, the side, the level and the
                extent that level would cover.
        """
        for level, stride in enumerate(self.level_strides):
            for side in shape:
                if side % stride:
                    covered = math.ceil(side / stride) * stride
                    raise ValueError(
                        f'TPVPlaneEncoder: the {name} plane {tuple(shape)} '
                        f'has a side of {side} cells, not a multiple of '
                        f'level {level}\'s stride {stride}: that level '
                        f'would cover {covered} cells (padded at the '
                        'end) and be sampled out of register. Choose '
                        f'plane sides divisible by {self.level_strides[-1]}')

    def forward(self,
                planes: Sequence[Tensor]) -> List[Tuple[Tensor, ...]]:
        """Encode the planes.

        Args:
            planes (Sequence[Tensor]): The three planes, each
                Shape (B, C, H_k, W_k).

        Returns:
            list[tuple[Tensor]]: One entry per scale (finest first), each
            holding the three planes of that scale, plane ``k`` of
            Shape (B, C_out, H_k / s_l, W_k / s_l) at the level's stride
            ``s_l``.
        """
        if len(planes) != 3:
            raise ValueError('TPVPlaneEncoder expects three planes, got '
                             f'{len(planes)}')
        per_plane = []
        for k, plane in enumerate(planes):
            levels = self.backbone(plane)
            for level, (feat, stride) in enumerate(
                    zip(levels, self.level_strides)):
                extent = tuple(s * stride for s in feat.shape[-2:])
                if extent != tuple(plane.shape[-2:]):
                    raise ValueError(
                        f'TPVPlaneEncoder: level {level} of plane {k} '
                        f'covers {extent} cells, the plane has '
                        f'{tuple(plane.shape[-2:])}')
            per_plane.append(self.neck(levels))
        return [tuple(level) for level in zip(*per_plane)]
