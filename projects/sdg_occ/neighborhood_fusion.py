"""Neighbourhood cross-attention fusion of two BEV maps.

Implements eqs. 3-4 of SDG-OCC (Duan et al., CVPR 2025, Sec. 3.3): the
source BEV gives the queries, the cross BEV gives keys and values over a
k x k neighbourhood of every cell (neighbourhood attention with a learned
relative positional bias, eq. 3), and the fused map is re-weighted by a
channel gate ``sigmoid(Conv(AvgPool(F))) * F`` (eq. 4).
"""
import math
from typing import Optional

import torch
import torch.nn.functional as F
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import Tensor, nn


def neighborhood_attention(query: Tensor, key: Tensor, value: Tensor,
                           rel_bias: Tensor, kernel_size: int) -> Tensor:
    """Multi-head attention of each cell over its k x k neighbourhood.

    ``out[i] = sum_j softmax_j(q_i . k_j / sqrt(d) + bias[j - i]) v_j`` for
    the cells j of the window centred on i. Windows are centred and cells
    outside the map are masked out (not clamped as in NATTEN), so window
    slot s always holds the same relative offset and the bias is a table of
    k * k values per head. The loop runs over the k * k offsets, each a
    whole-map tensor operation, so memory stays O(B * C * H * W) instead
    of the O(k^2 B C H W) of an unfolded key tensor.

    Args:
        query (Tensor): Shape (B, heads, d, H, W).
        key (Tensor): Shape (B, heads, d, H, W).
        value (Tensor): Shape (B, heads, d_v, H, W).
        rel_bias (Tensor): Bias per head and window slot (row-major over the
            k x k offsets). Shape (heads, k * k).
        kernel_size (int): Odd window size k.

    Returns:
        Tensor: Attended values. Shape (B, heads, d_v, H, W).
    """
    if kernel_size < 1 or kernel_size % 2 == 0:
        raise ValueError(f'kernel_size must be odd and >= 1, got '
                         f'{kernel_size}')
    if query.dim() != 5 or key.shape != query.shape:
        raise ValueError('query and key must both have shape (B, heads, d, '
                         f'H, W), got {tuple(query.shape)} and '
                         f'{tuple(key.shape)}')
    if value.dim() != 5 or value.shape[:2] != query.shape[:2] \
            or value.shape[3:] != query.shape[3:]:
        raise ValueError('value must have shape (B, heads, d_v, H, W) '
                         f'matching query {tuple(query.shape)}, got '
                         f'{tuple(value.shape)}')
    num_heads = query.shape[1]
    if rel_bias.shape != (num_heads, kernel_size * kernel_size):
        raise ValueError(f'rel_bias must have shape ({num_heads}, '
                         f'{kernel_size * kernel_size}), got '
                         f'{tuple(rel_bias.shape)}')
    height, width = query.shape[-2:]
    reach = kernel_size // 2
    pad = (reach, reach, reach, reach)
    key_pad = F.pad(key, pad)
    value_pad = F.pad(value, pad)
    inside = F.pad(
        query.new_ones(height, width, dtype=torch.bool), pad, value=False)
    scale = 1.0 / math.sqrt(query.shape[2])

    logits = []
    for slot in range(kernel_size * kernel_size):
        row, col = divmod(slot, kernel_size)
        window = (slice(row, row + height), slice(col, col + width))
        logit = (query * key_pad[..., window[0], window[1]]).sum(2) * scale
        logit = logit + rel_bias[:, slot].view(1, num_heads, 1, 1)
        logits.append(
            logit.masked_fill(~inside[window], float('-inf')))
    attn = torch.stack(logits, dim=2).softmax(dim=2)

    out = 0
    for slot in range(kernel_size * kernel_size):
        row, col = divmod(slot, kernel_size)
        out = out + attn[:, :, slot:slot + 1] * value_pad[
            ..., row:row + height, col:col + width]
    return out


@MODELS.register_module()
class NeighborhoodFusion(BaseModule):
    """Fuse a source BEV with a cross BEV by neighbourhood attention.

    Implements eqs. 3-4 of SDG-OCC. The attended cross features are
    concatenated with the source features, mixed by a 3x3 conv, and gated
    per channel by ``sigmoid(Conv1x1(AvgPool(F)))``.

    Args:
        source_channels (int): Channels of the source BEV (queries).
        cross_channels (int): Channels of the cross BEV (keys, values).
        out_channels (int): Channels of the fused BEV.
        embed_dims (int): Attention width, split over the heads.
            Defaults to 64.
        num_heads (int): Attention heads. Defaults to 4.
        kernel_size (int): Neighbourhood size k (7 in the paper, Table 5).
            Defaults to 7.
        init_cfg (dict, optional): mmengine initialisation config.
    """

    def __init__(self,
                 source_channels: int,
                 cross_channels: int,
                 out_channels: int,
                 embed_dims: int = 64,
                 num_heads: int = 4,
                 kernel_size: int = 7,
                 init_cfg: Optional[dict] = None):
        super().__init__(init_cfg=init_cfg)
        if embed_dims % num_heads != 0:
            raise ValueError(f'embed_dims ({embed_dims}) must be divisible '
                             f'by num_heads ({num_heads})')
        if kernel_size < 1 or kernel_size % 2 == 0:
            raise ValueError(f'kernel_size must be odd and >= 1, got '
                             f'{kernel_size}')
        self.num_heads = num_heads
        self.kernel_size = kernel_size
        self.query = nn.Conv2d(source_channels, embed_dims, 1)
        self.key = nn.Conv2d(cross_channels, embed_dims, 1)
        self.value = nn.Conv2d(cross_channels, embed_dims, 1)
        self.rel_bias = nn.Parameter(
            torch.zeros(num_heads, kernel_size * kernel_size))
        nn.init.trunc_normal_(self.rel_bias, std=0.02)
        self.proj = nn.Conv2d(embed_dims, out_channels, 1)
        self.mix = nn.Sequential(
            nn.Conv2d(
                source_channels + out_channels,
                out_channels,
                3,
                padding=1,
                bias=False), nn.BatchNorm2d(out_channels),
            nn.ReLU(inplace=True))
        self.gate = nn.Sequential(
            nn.AdaptiveAvgPool2d(1), nn.Conv2d(out_channels, out_channels, 1),
            nn.Sigmoid())

    def _heads(self, x: Tensor) -> Tensor:
        batch, channels, height, width = x.shape
        return x.view(batch, self.num_heads, channels // self.num_heads,
                      height, width)

    def forward(self, source: Tensor, cross: Tensor) -> Tensor:
        """Fuse ``cross`` into ``source``.

        Args:
            source (Tensor): Query BEV. Shape (B, C_s, H, W).
            cross (Tensor): Key/value BEV. Shape (B, C_c, H, W).

        Returns:
            Tensor: Fused BEV. Shape (B, C_out, H, W).
        """
        if source.dim() != 4 or cross.dim() != 4 \
                or source.shape[0] != cross.shape[0] \
                or source.shape[2:] != cross.shape[2:]:
            raise ValueError('NeighborhoodFusion expects source (B, C_s, H, '
                             'W) and cross (B, C_c, H, W) on the same grid, '
                             f'got {tuple(source.shape)} and '
                             f'{tuple(cross.shape)}')
        attended = neighborhood_attention(
            self._heads(self.query(source)), self._heads(self.key(cross)),
            self._heads(self.value(cross)), self.rel_bias, self.kernel_size)
        attended = self.proj(attended.flatten(1, 2))
        fused = self.mix(torch.cat([source, attended], dim=1))
        return fused * self.gate(fused)
