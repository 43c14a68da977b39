"""BEVDepth-style depth and context network (OccCylindrical eq. 5).

Shared by OccCylindrical and SDG-OCC. Given image features ``V`` it predicts

* ``depth``: a softmax distribution ``V_depth`` over ``D`` depth bins,
* ``context``: ``V_context = V + CNN1(V_depth) + CNN2(V_coord)`` (eq. 5 of
  OccCylindrical), where ``V_coord`` is a position embedding of the bins'
  3D points (see
  :func:`~projects.occ_common.models.layers.camera_geometry.cylindrical_position_embedding`),
* optionally ``seg_logits``: per-pixel semantic logits (SDG-OCC's
  segmentation head), from the same reduced features.
"""
from typing import Dict, Optional, Sequence

import torch
import torch.nn.functional as F
from mmcv.cnn import ConvModule, build_norm_layer
from mmdet3d.registry import MODELS
from mmdet3d.utils import ConfigType, OptMultiConfig
from mmengine.model import BaseModule
from torch import Tensor, nn

from ...geometry.depth import normalize_depth_bound
from ...geometry.depth import num_depth_bins as num_depth_bins_of
from .checkpointing import checkpoint_if_grad


class _ResBlock(nn.Module):
    """3x3-3x3 residual block of BEVDepth's depth branch.

    Args:
        channels (int): Input and output channels.
        norm_cfg (dict): Normalisation config.
    """

    def __init__(self, channels: int, norm_cfg: ConfigType) -> None:
        super().__init__()
        self.conv1 = ConvModule(
            channels, channels, 3, padding=1, norm_cfg=norm_cfg)
        self.conv2 = ConvModule(
            channels, channels, 3, padding=1, norm_cfg=norm_cfg, act_cfg=None)

    def forward(self, x: Tensor) -> Tensor:
        """Shape (B, C, H, W) -> (B, C, H, W)."""
        return F.relu(x + self.conv2(self.conv1(x)))


class _ASPP(nn.Module):
    """Atrous spatial pyramid pooling (DeepLabV3), as in BEVDepth.

    Args:
        channels (int): Input and output channels.
        dilations (Sequence[int]): Dilation of each branch; 1 is a 1x1 conv.
        norm_cfg (dict): Normalisation config.
    """

    def __init__(self, channels: int, dilations: Sequence[int],
                 norm_cfg: ConfigType) -> None:
        super().__init__()
        self.branches = nn.ModuleList([
            ConvModule(
                channels,
                channels,
                1 if dil == 1 else 3,
                padding=0 if dil == 1 else dil,
                dilation=dil,
                norm_cfg=norm_cfg) for dil in dilations
        ])
        # The image-level branch uses no norm: after global pooling a batch
        # of one image has a single value per channel and BN would fail.
        self.image_pool = nn.Sequential(
            nn.AdaptiveAvgPool2d(1), nn.Conv2d(channels, channels, 1),
            nn.ReLU(inplace=True))
        self.project = ConvModule(
            channels * (len(dilations) + 1), channels, 1, norm_cfg=norm_cfg)

    def forward(self, x: Tensor) -> Tensor:
        """Shape (B, C, H, W) -> (B, C, H, W)."""
        outs = [branch(x) for branch in self.branches]
        outs.append(self.image_pool(x).expand(-1, -1, *x.shape[2:]))
        return self.project(torch.cat(outs, dim=1))


class _CameraSE(nn.Module):
    """Camera-aware squeeze-and-excitation gate of BEVDepth.

    Args:
        param_dims (int): Length of the camera parameter vector.
        channels (int): Channels of the gated features.
    """

    def __init__(self, param_dims: int, channels: int) -> None:
        super().__init__()
        self.mlp = nn.Sequential(
            nn.Linear(param_dims, channels), nn.ReLU(inplace=True),
            nn.Linear(channels, channels))

    def forward(self, x: Tensor, params: Tensor) -> Tensor:
        """Gate features (B, C, H, W) by parameters (B, K)."""
        return x * torch.sigmoid(self.mlp(params))[..., None, None]


@MODELS.register_module()
class DepthNet(BaseModule):
    """Depth distribution, context features and optional segmentation.

    Implements eq. 5 of OccCylindrical on top of BEVDepth's DepthNet: a 3x3
    reduction, a depth branch (residual blocks, ASPP, 1x1 classifier; the
    deformable conv of BEVDepth is replaced by a plain 3x3 conv so that the
    network runs without compiled ops) and a context branch. ``V`` of eq. 5
    is the reduced feature map projected to ``context_channels`` by a 1x1
    conv, then

    ``V_context = V + CNN1(V_depth) + CNN2(V_coord)``.

    Each term can be switched off for the ablations of Table V.

    SDG-OCC adds its semantic head either with ``seg_channels`` or by
    subclassing and overriding :meth:`forward_seg`.

    Args:
        in_channels (int): Channels of the image features.
        mid_channels (int): Channels inside the network.
        context_channels (int): Channels ``C`` of ``V_context``.
        num_depth_bins (int, optional): Number of depth bins ``D``; may be
            left out when ``depth_bound`` is given.
        depth_bound (Sequence[float], optional): ``(min, max, step)`` of the
            bins in metres, from which ``D`` is derived (the detectors pass
            their own). Defaults to None.
        position_channels (int): Channels of ``V_coord``
            (``POSITION_EMBED_DIMS * D`` = ``4 * D`` for the cylindrical
            embedding); 0 drops the ``CNN2(V_coord)`` term.
            Defaults to 0.
        with_depth_feature (bool): Add ``CNN1(V_depth)``. Defaults to True.
        camera_param_dims (int): Length of the camera parameter vector for
            BEVDepth's camera-aware gates; 0 disables them. Defaults to 0.
        seg_channels (int): Number of semantic classes of the optional
            segmentation head; 0 disables it. Defaults to 0.
        num_res_blocks (int): Residual blocks in the depth branch.
            Defaults to 3 (BEVDepth).
        aspp_dilations (Sequence[int]): ASPP dilations; empty disables ASPP.
            Defaults to (1, 6, 12, 18) (BEVDepth).
        norm_cfg (dict): Normalisation config. Defaults to BN.
        with_cp (bool): In training, keep only the depth branch's input
            for the backward and recompute the branch there (exact: its
            BatchNorms update their statistics once, see
            :func:`~.checkpointing.checkpoint_if_grad`). At BEVDepth's
            width (512) and 6 x 928 x 1600 images the branch otherwise
            keeps ~28 maps of 68 MiB. Defaults to False.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 in_channels: int,
                 mid_channels: int,
                 context_channels: int,
                 num_depth_bins: Optional[int] = None,
                 depth_bound: Optional[Sequence[float]] = None,
                 position_channels: int = 0,
                 with_depth_feature: bool = True,
                 camera_param_dims: int = 0,
                 seg_channels: int = 0,
                 num_res_blocks: int = 3,
                 aspp_dilations: Sequence[int] = (1, 6, 12, 18),
                 norm_cfg: ConfigType = dict(type='BN'),
                 with_cp: bool = False,
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(init_cfg=init_cfg)
        self.with_cp = with_cp
        self.depth_bound = None
        if depth_bound is not None:
            self.depth_bound = normalize_depth_bound(depth_bound)
            derived = num_depth_bins_of(depth_bound)
            if num_depth_bins not in (None, derived):
                raise ValueError(f'DepthNet: num_depth_bins={num_depth_bins} '
                                 f'but depth_bound {depth_bound} gives '
                                 f'{derived} bins')
            num_depth_bins = derived
        if num_depth_bins is None:
            raise ValueError('DepthNet needs depth_bound or num_depth_bins')
        for name, value in (('in_channels', in_channels),
                            ('mid_channels', mid_channels),
                            ('context_channels', context_channels),
                            ('num_depth_bins', num_depth_bins)):
            if int(value) != value or value < 1:
                raise ValueError(f'DepthNet: {name} must be a positive '
                                 f'integer, got {value!r}')
        self.num_depth_bins = num_depth_bins
        self.context_channels = context_channels
        self.position_channels = position_channels
        self.with_depth_feature = with_depth_feature
        self.camera_param_dims = camera_param_dims
        self.seg_channels = seg_channels

        self.reduce_conv = ConvModule(
            in_channels, mid_channels, 3, padding=1, norm_cfg=norm_cfg)
        if camera_param_dims > 0:
            # BatchNorm1d normalises raw focal lengths (~1000) and metres.
            self.cam_param_norm = build_norm_layer(
                dict(type='BN1d'), camera_param_dims)[1]
            self.depth_se = _CameraSE(camera_param_dims, mid_channels)
            self.context_se = _CameraSE(camera_param_dims, mid_channels)
        depth_layers = [
            _ResBlock(mid_channels, norm_cfg) for _ in range(num_res_blocks)
        ]
        if len(aspp_dilations) > 0:
            depth_layers.append(_ASPP(mid_channels, aspp_dilations, norm_cfg))
        depth_layers += [
            ConvModule(
                mid_channels, mid_channels, 3, padding=1, norm_cfg=norm_cfg),
            nn.Conv2d(mid_channels, num_depth_bins, 1)
        ]
        self.depth_branch = nn.Sequential(*depth_layers)
        self.context_conv = nn.Conv2d(mid_channels, context_channels, 1)
        if with_depth_feature:
            self.depth_embed = self._embed(num_depth_bins, context_channels,
                                           norm_cfg)
        if position_channels > 0:
            self.position_embed = self._embed(position_channels,
                                              context_channels, norm_cfg)
        if seg_channels > 0:
            self.seg_head = nn.Sequential(
                ConvModule(
                    mid_channels,
                    mid_channels,
                    3,
                    padding=1,
                    norm_cfg=norm_cfg), nn.Conv2d(mid_channels, seg_channels,
                                                  1))

    @staticmethod
    def _embed(in_channels: int, out_channels: int,
               norm_cfg: ConfigType) -> nn.Module:
        """CNN1 / CNN2 of eq. 5: 1x1 conv-BN-ReLU then a 1x1 projection."""
        return nn.Sequential(
            ConvModule(in_channels, out_channels, 1, norm_cfg=norm_cfg),
            nn.Conv2d(out_channels, out_channels, 1))

    def forward(self,
                x: Tensor,
                pos_embed: Optional[Tensor] = None,
                cam_params: Optional[Tensor] = None) -> Dict[str, Tensor]:
        """Predict depth, context and (optionally) segmentation.

        Args:
            x (Tensor): Image features ``V``. Shape (B*N, C_in, h, w).
            pos_embed (Tensor, optional): ``V_coord``; required when
                ``position_channels > 0``. Shape (B*N, position_channels,
                h, w).
            cam_params (Tensor, optional): Camera parameters; required when
                ``camera_param_dims > 0``. Shape (B*N, camera_param_dims).

        Returns:
            dict[str, Tensor]: ``depth`` (softmax over bins), shape
            (B*N, D, h, w); ``depth_logits``, same shape; ``context``, shape
            (B*N, context_channels, h, w); and ``seg_logits``, shape
            (B*N, seg_channels, h, w), when the segmentation head is on.
        """
        if x.dim() != 4:
            raise ValueError('DepthNet expects features (B*N, C, h, w), got '
                             f'{tuple(x.shape)}')
        feats = self.reduce_conv(x)
        depth_feats = context_feats = feats
        if self.camera_param_dims > 0:
            expected = (x.shape[0], self.camera_param_dims)
            if cam_params is None or tuple(cam_params.shape) != expected:
                got = None if cam_params is None else tuple(cam_params.shape)
                raise ValueError(f'DepthNet: cam_params of shape {expected} '
                                 f'required, got {got}')
            params = self.cam_param_norm(cam_params.to(feats))
            depth_feats = self.depth_se(feats, params)
            context_feats = self.context_se(feats, params)
        depth_logits = checkpoint_if_grad(
            self.with_cp, self.depth_branch, depth_feats,
            module=self.depth_branch)
        depth = depth_logits.softmax(dim=1)
        context = self.context_conv(context_feats)
        if self.with_depth_feature:
            context = context + self.depth_embed(depth)
        if self.position_channels > 0:
            expected = (x.shape[0], self.position_channels, *x.shape[2:])
            if pos_embed is None or tuple(pos_embed.shape) != expected:
                got = None if pos_embed is None else tuple(pos_embed.shape)
                raise ValueError(f'DepthNet: pos_embed of shape {expected} '
                                 f'required, got {got}')
            context = context + self.position_embed(pos_embed.to(context))
        out = dict(depth=depth, depth_logits=depth_logits, context=context)
        seg_logits = self.forward_seg(feats)
        if seg_logits is not None:
            out['seg_logits'] = seg_logits
        return out

    def forward_seg(self, feats: Tensor) -> Optional[Tensor]:
        """Semantic logits of the reduced features, or None without a head.

        Subclasses may override this to attach a different segmentation
        head.

        Args:
            feats (Tensor): Reduced features. Shape (B*N, mid_channels, h, w).

        Returns:
            Tensor or None: Logits. Shape (B*N, seg_channels, h, w).
        """
        if self.seg_channels > 0:
            return self.seg_head(feats)
        return None
