"""Shared Swin + FPN encoder-decoder over the three TPV-polar planes."""
from typing import List, Sequence, Tuple

from mmdet3d.registry import MODELS
from mmdet3d.utils import ConfigType, OptMultiConfig
from mmengine.model import BaseModule
from torch import Tensor


@MODELS.register_module()
class TPVPlaneEncoder(BaseModule):
    """Encode each TPV-polar plane with one shared backbone and neck.

    Implements eqs. 14-16 of OccCylindrical: the same 2D backbone
    (``mmdet.SwinTransformer``, tiny in the paper) and the same
    ``mmdet.FPN`` process the (R, Theta), (Theta, Z) and (R, Z) planes,
    giving multi-scale features for each. The planes differ in size, so they
    pass through the shared weights one after the other.

    Args:
        backbone (dict): Backbone config; its ``in_channels`` must equal the
            plane channels.
        neck (dict): Neck config producing ``num_outs`` levels.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 backbone: ConfigType,
                 neck: ConfigType,
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(init_cfg=init_cfg)
        self.backbone = MODELS.build(backbone)
        self.neck = MODELS.build(neck)

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
        per_plane = [self.neck(self.backbone(plane)) for plane in planes]
        return [tuple(level) for level in zip(*per_plane)]
