"""Neighbourhood cross-attention fusion of two BEV maps.

Implements eqs. 3-4 of SDG-OCC (Duan et al., CVPR 2025, Sec. 3.5): the
source BEV gives the queries, the cross BEV gives keys and values over a
k x k neighbourhood of every cell (neighbourhood attention with a learned
relative positional bias, eq. 3), and the fused map is re-weighted by a
channel gate ``sigmoid(Conv(AvgPool(F))) * F`` (eq. 4). Which BEV is the
source is the detector's choice: the camera BEV for SDG-Fusion, the LiDAR
BEV for SDG-KL's teacher.
"""
import math
from typing import Optional

import torch
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import Tensor, nn

#: How a window meets the map border: ``'shift'`` moves it inside the map
#: (NAT, Hassani et al., CVPR 2023, ref. [3] of SDG-OCC: every query sees
#: k * k keys); ``'mask'`` keeps it centred and drops the cells outside.
BORDERS = ('shift', 'mask')


def window_starts(size: int, kernel_size: int, border: str,
                  device=None) -> Tensor:
    """First row (or column) of the window of every query position.

    ``'shift'``: ``clamp(i - k // 2, 0, size - k)``, NATTEN's window start
    for dilation 1, so the window stays inside the map; on a map smaller
    than the window it starts at 0 and the cells past the end are masked.
    ``'mask'``: ``i - k // 2``, the centred window.

    Args:
        size (int): Length of the axis.
        kernel_size (int): Odd window size k.
        border (str): One of :data:`BORDERS`.
        device (torch.device, optional): Device of the result.

    Returns:
        Tensor: Long starts. Shape (size,).
    """
    if border not in BORDERS:
        raise ValueError(f'border must be one of {BORDERS}, got {border!r}')
    pos = torch.arange(size, device=device)
    start = pos - kernel_size // 2
    if border == 'shift':
        start = start.clamp(min=0).clamp(max=max(size - kernel_size, 0))
    return start


def neighborhood_attention(query: Tensor,
                           key: Tensor,
                           value: Tensor,
                           rel_bias: Tensor,
                           kernel_size: int,
                           border: str = 'shift') -> Tensor:
    """Multi-head attention of each cell over a k x k window (eq. 3).

    ``out[i] = sum_j softmax_j(q_i . k_j / sqrt(d) + B[j - i]) v_j`` over
    the cells j of the window of i (see :func:`window_starts`). The
    relative positional bias is NAT's table of (2k - 1) x (2k - 1) entries
    per head, indexed by the offset ``j - i + k - 1`` per axis: a shifted
    window at the border reaches offsets up to k - 1, a centred one only up
    to k // 2.

    The cells whose centred window lies inside the map (all but a border
    of k // 2 cells) are computed with whole-block slices of the keys and
    values, one per window slot, as views; the border strips, where the
    two rules differ, gather their windows' keys explicitly. Memory stays
    O(k^2 B heads H W) for the logits; no unfolded (k^2 B C H W) key
    tensor is ever built.

    Args:
        query (Tensor): Shape (B, heads, d, H, W).
        key (Tensor): Shape (B, heads, d, H, W).
        value (Tensor): Shape (B, heads, d_v, H, W).
        rel_bias (Tensor): Bias per head and offset (row, column).
            Shape (heads, 2k - 1, 2k - 1).
        kernel_size (int): Odd window size k.
        border (str): One of :data:`BORDERS`. Defaults to 'shift'.

    Returns:
        Tensor: Attended values. Shape (B, heads, d_v, H, W).
    """
    if kernel_size < 1 or kernel_size % 2 == 0:
        raise ValueError(f'kernel_size must be odd and >= 1, got '
                         f'{kernel_size}')
    if border not in BORDERS:
        raise ValueError(f'border must be one of {BORDERS}, got {border!r}')
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
    span = 2 * kernel_size - 1
    if rel_bias.shape != (num_heads, span, span):
        raise ValueError(f'rel_bias must have shape ({num_heads}, {span}, '
                         f'{span}), got {tuple(rel_bias.shape)}')
    height, width = query.shape[-2:]
    reach = kernel_size // 2
    device = query.device

    def strip(rows: range, cols: range) -> Tensor:
        return _attend_gathered(query, key, value, rel_bias, kernel_size,
                                border, torch.arange(rows.start, rows.stop,
                                                     device=device),
                                torch.arange(cols.start, cols.stop,
                                             device=device))

    if height < kernel_size or width < kernel_size:
        return strip(range(height), range(width))
    inner = _attend_inner(query, key, value, rel_bias, kernel_size)
    if reach == 0:
        return inner
    middle = torch.cat([
        strip(range(reach, height - reach), range(reach)), inner,
        strip(range(reach, height - reach), range(width - reach, width))
    ], dim=4)
    return torch.cat([
        strip(range(reach), range(width)), middle,
        strip(range(height - reach, height), range(width))
    ], dim=3)


#: Bytes of key rows one block of :func:`_attend_inner` reads: small
#: enough for a CPU core's L2 cache, where the 2 k^2 passes over the block
#: run about twice as fast (paper size, 64 channels x 200 columns: 20 rows;
#: issue 18 measured 267 -> 145 ms for the interior).
BLOCK_BYTES = 1 << 20


def _attend_inner(query: Tensor, key: Tensor, value: Tensor,
                  rel_bias: Tensor, kernel_size: int) -> Tensor:
    """:func:`_attend_inner_block` over blocks of rows of the map.

    Every output cell is computed exactly as in one block (the same
    products and sums in the same order); only the order in which cells
    are visited changes, so that each block's keys and values stay in
    cache across the k^2 window slots.

    Returns:
        Tensor: Shape (B, heads, d_v, H - 2r, W - 2r).
    """
    reach = kernel_size // 2
    out_h = query.shape[-2] - 2 * reach
    row_bytes = key[..., 0, :].numel() * key.element_size()
    rows = max(1, BLOCK_BYTES // max(row_bytes, 1) - 2 * reach)
    if rows >= out_h:
        return _attend_inner_block(query, key, value, rel_bias, kernel_size)
    return torch.cat([
        _attend_inner_block(
            *(t[..., start:min(start + rows, out_h) + 2 * reach, :]
              for t in (query, key, value)), rel_bias, kernel_size)
        for start in range(0, out_h, rows)
    ], dim=3)


def _attend_inner_block(query: Tensor, key: Tensor, value: Tensor,
                        rel_bias: Tensor, kernel_size: int) -> Tensor:
    """Attention of the cells whose centred window lies inside the map.

    Query (i, j), i in [r, H - r), j in [r, W - r), slot (a, c) sees key
    (i - r + a, j - r + c): for all of them at once, the block
    ``key[..., a:a + H - 2r, c:c + W - 2r]`` (a view), with the bias at
    offset (a - r, c - r), table index (a + r, c + r).

    Returns:
        Tensor: Shape (B, heads, d_v, H - 2r, W - 2r).
    """
    height, width = query.shape[-2:]
    reach = kernel_size // 2
    out_h, out_w = height - 2 * reach, width - 2 * reach
    queries = query[..., reach:reach + out_h, reach:reach + out_w]
    scale = 1.0 / math.sqrt(query.shape[2])
    slots = [divmod(s, kernel_size) for s in range(kernel_size**2)]
    logits = [(queries * key[..., a:a + out_h, c:c + out_w]).sum(2) * scale
              + rel_bias[:, a + reach, c + reach].view(1, -1, 1, 1)
              for a, c in slots]
    attn = torch.stack(logits, dim=2).softmax(dim=2)
    out = 0
    for slot, (a, c) in enumerate(slots):
        out = out + attn[:, :, slot:slot + 1] * value[..., a:a + out_h,
                                                      c:c + out_w]
    return out


def _attend_gathered(query: Tensor, key: Tensor, value: Tensor,
                     rel_bias: Tensor, kernel_size: int, border: str,
                     rows: Tensor, cols: Tensor) -> Tensor:
    """Attention of the query cells ``rows x cols``, windows gathered.

    Returns:
        Tensor: Shape (B, heads, d_v, len(rows), len(cols)).
    """
    height, width = query.shape[-2:]
    queries = query.index_select(3, rows).index_select(4, cols)
    key_rows, row_in, bias_rows = _window_slots(height, kernel_size, border,
                                                rows)
    key_cols, col_in, bias_cols = _window_slots(width, kernel_size, border,
                                                cols)
    scale = 1.0 / math.sqrt(query.shape[2])
    logits = []
    for a in range(kernel_size):
        keys_a = key.index_select(3, key_rows[a])
        bias_a = rel_bias[:, bias_rows[a]]
        for c in range(kernel_size):
            logit = (queries * keys_a.index_select(4, key_cols[c])).sum(2)
            logit = logit * scale + bias_a[:, :, bias_cols[c]]
            inside = row_in[a].view(-1, 1) & col_in[c].view(1, -1)
            logits.append(logit.masked_fill(~inside, float('-inf')))
    attn = torch.stack(logits, dim=2).softmax(dim=2)
    out = 0
    for a in range(kernel_size):
        values_a = value.index_select(3, key_rows[a])
        for c in range(kernel_size):
            slot = a * kernel_size + c
            out = out + attn[:, :, slot:slot + 1] * values_a.index_select(
                4, key_cols[c])
    return out


def _window_slots(size: int, kernel_size: int, border: str,
                  positions: Tensor):
    """Key index, inside-map flag and bias index per window slot.

    Args:
        size (int): Length of the axis.
        kernel_size (int): Odd window size k.
        border (str): One of :data:`BORDERS`.
        positions (Tensor): Query positions on the axis. Shape (P,).

    Returns:
        tuple[Tensor, Tensor, Tensor]: Each Shape (k, P): the key position
        clamped into the map, whether it lies inside, and
        ``key - query + k - 1``.
    """
    start = window_starts(size, kernel_size, border, positions.device)
    keys = start[positions].view(1, -1) + torch.arange(
        kernel_size, device=positions.device).view(-1, 1)
    inside = (keys >= 0) & (keys < size)
    bias = keys - positions.view(1, -1) + kernel_size - 1
    return keys.clamp(0, size - 1), inside, bias


@MODELS.register_module()
class NeighborhoodFusion(BaseModule):
    """Fuse a source BEV with a cross BEV by neighbourhood attention.

    Implements eqs. 3-4 of SDG-OCC: the source gives the queries, the cross
    BEV the keys and values (eq. 3); the attended cross features are
    concatenated with the source features, mixed by a 3x3 conv-BN-ReLU and
    gated per channel, ``F * sigmoid(Conv1x1(AvgPool(F)))`` (eq. 4).

    Eq. 4 writes the gate on ``F_neighbor``, the attention output alone;
    that would leave the source's own features out of the fused map except
    through the attention weights. The gate here acts on the mix of both
    (the source and its attended cross features), as the authors' released
    code does (a 3x3 conv over the concatenation, then the pooled sigmoid
    gate).

    Args:
        source_channels (int): Channels of the source BEV (queries).
        cross_channels (int): Channels of the cross BEV (keys, values).
        out_channels (int): Channels of the fused BEV.
        embed_dims (int): Attention width, split over the heads.
            Defaults to 64.
        num_heads (int): Attention heads. Defaults to 4.
        kernel_size (int): Neighbourhood size k (7 in the paper, Table 5).
            Defaults to 7.
        border (str): Windows at the map border, one of :data:`BORDERS`:
            ``'shift'`` (NAT's, ref. [3], every query sees k * k keys) or
            ``'mask'`` (centred, cells outside the map dropped).
            Defaults to 'shift'.
        init_cfg (dict, optional): mmengine initialisation config.
    """

    def __init__(self,
                 source_channels: int,
                 cross_channels: int,
                 out_channels: int,
                 embed_dims: int = 64,
                 num_heads: int = 4,
                 kernel_size: int = 7,
                 border: str = 'shift',
                 init_cfg: Optional[dict] = None):
        super().__init__(init_cfg=init_cfg)
        if embed_dims % num_heads != 0:
            raise ValueError(f'embed_dims ({embed_dims}) must be divisible '
                             f'by num_heads ({num_heads})')
        if kernel_size < 1 or kernel_size % 2 == 0:
            raise ValueError(f'kernel_size must be odd and >= 1, got '
                             f'{kernel_size}')
        if border not in BORDERS:
            raise ValueError(f'NeighborhoodFusion border must be one of '
                             f'{BORDERS}, got {border!r}')
        self.source_channels = source_channels
        self.cross_channels = cross_channels
        self.out_channels = out_channels
        self.num_heads = num_heads
        self.kernel_size = kernel_size
        self.border = border
        self.query = nn.Conv2d(source_channels, embed_dims, 1)
        self.key = nn.Conv2d(cross_channels, embed_dims, 1)
        self.value = nn.Conv2d(cross_channels, embed_dims, 1)
        span = 2 * kernel_size - 1
        self.rel_bias = nn.Parameter(torch.zeros(num_heads, span, span))
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
        if source.shape[1] != self.source_channels \
                or cross.shape[1] != self.cross_channels:
            raise ValueError(
                f'NeighborhoodFusion expects {self.source_channels} source '
                f'(query) and {self.cross_channels} cross (key / value) '
                f'channels, got {source.shape[1]} and {cross.shape[1]}')
        attended = neighborhood_attention(
            self._heads(self.query(source)), self._heads(self.key(cross)),
            self._heads(self.value(cross)), self.rel_bias, self.kernel_size,
            self.border)
        attended = self.proj(attended.flatten(1, 2))
        fused = self.mix(torch.cat([source, attended], dim=1))
        return fused * self.gate(fused)
