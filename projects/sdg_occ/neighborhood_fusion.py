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
from collections import OrderedDict
from typing import NamedTuple, Optional

import torch
import torch.nn.functional as F
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import Tensor, nn

from projects.occ_common.utils.device_path import accelerator_path

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
    # Scaled once here (not per window slot): one multiplication of the
    # queries instead of one per slot and block.
    query = query * (1.0 / math.sqrt(query.shape[2]))
    edge = _border_cells(height, width, kernel_size, border, query.device)
    out = _attend_cells(query, key, value, rel_bias, edge)
    if edge.interior:
        inner = _attend_inner(query, key, value, rel_bias, kernel_size)
        # Disjoint supports: the border cells are 0 in the padded interior
        # and the interior cells 0 in ``out``, so the sum is exact.
        out = out + F.pad(inner, (reach, reach, reach, reach))
    return out


class BorderCells(NamedTuple):
    """The gathered windows of the cells outside the interior.

    The interior (cells whose centred window lies inside the map, both
    border rules agree there) is computed with strided views of the keys;
    the other cells, where a window is shifted or masked, gather their
    keys with these indices, built once per map shape and device.

    Attributes:
        cells (Tensor): Flat index ``i * W + j`` of each border cell.
            Shape (P,).
        keys (Tensor): Flat index of each cell's window keys (slot
            ``a * k + c`` for window row a, column c), clamped into the
            map. Shape (P * k * k,).
        inside (Tensor): Whether that key lies inside the map. Shape
            (P, k * k).
        bias (Tensor): Flat index of the relative-bias table entry
            ``(row offset + k - 1) * (2k - 1) + column offset + k - 1``.
            Shape (P, k * k).
        size (int): ``H * W``.
        interior (bool): Whether the map has interior cells.
    """
    cells: Tensor
    keys: Tensor
    inside: Tensor
    bias: Tensor
    size: int
    interior: bool


_BORDER_CACHE: 'OrderedDict[tuple, BorderCells]' = OrderedDict()
#: Map shapes whose border indices are kept (per device and rule).
BORDER_CACHE_SIZE = 8


def _border_cells(height: int, width: int, kernel_size: int, border: str,
                  device) -> BorderCells:
    """:class:`BorderCells` of a map, from a small cache: the indices are
    built once per shape, not per call. Code being compiled builds them in
    its graph instead (from the shape alone, so the compiler may fold them
    to constants) and leaves the cache alone."""
    key = (height, width, kernel_size, border, str(device))
    compiling = torch.compiler.is_compiling()
    cached = None if compiling else _BORDER_CACHE.get(key)
    if cached is not None:
        _BORDER_CACHE.move_to_end(key)
        return cached
    reach = kernel_size // 2
    interior = height > 2 * reach and width > 2 * reach
    rows = torch.arange(height)
    cols = torch.arange(width)
    outside = ((rows < reach) | (rows >= height - reach)).view(-1, 1) | \
        ((cols < reach) | (cols >= width - reach)).view(1, -1)
    num = height * width
    if interior:
        num -= (height - 2 * reach) * (width - 2 * reach)
    else:
        outside = torch.ones(height, width, dtype=torch.bool)
    # The border cells in row-major order, as nonzero lists them, with a
    # count known from the shape (nonzero's is data-dependent: a graph
    # break under torch.compile): sorted by (interior, index), keys all
    # distinct, so no stable sort is needed (ONNX has none).
    index = torch.arange(height * width)
    flat = torch.sort((~outside).flatten().long() * (height * width) +
                      index)[1][:num]
    cell_rows, cell_cols = flat // width, flat % width
    key_rows, row_in, bias_rows = _window_slots(height, kernel_size, border,
                                                cell_rows)
    key_cols, col_in, bias_cols = _window_slots(width, kernel_size, border,
                                                cell_cols)
    # (k, P) per axis -> (P, k, k) -> (P, k * k), slot a * k + c.
    span = 2 * kernel_size - 1
    keys = (key_rows.t()[:, :, None] * width + key_cols.t()[:, None, :])
    inside = row_in.t()[:, :, None] & col_in.t()[:, None, :]
    bias = bias_rows.t()[:, :, None] * span + bias_cols.t()[:, None, :]
    cells = BorderCells(
        cells=(cell_rows * width + cell_cols).to(device),
        keys=keys.flatten().to(device),
        inside=inside.flatten(1).to(device),
        bias=bias.flatten(1).to(device),
        size=height * width,
        interior=interior)
    if compiling:
        return cells
    _BORDER_CACHE[key] = cells
    while len(_BORDER_CACHE) > BORDER_CACHE_SIZE:
        _BORDER_CACHE.popitem(last=False)
    return cells


def _attend_cells(query: Tensor, key: Tensor, value: Tensor,
                  rel_bias: Tensor, edge: BorderCells) -> Tensor:
    """Attention of the border cells, their windows gathered at once.

    The query is already scaled by ``1 / sqrt(d)``. A fixed number of
    operations whatever the batch or map size (the previous border strips
    looped over the k * k slots with two gathers each).

    Returns:
        Tensor: The border cells' outputs, 0 at interior cells.
        Shape (B, heads, d_v, H, W).
    """
    batch, heads, dims = query.shape[:3]
    dims_v = value.shape[2]
    height, width = query.shape[-2:]
    num = edge.cells.numel()
    slots = edge.inside.shape[1]
    queries = query.flatten(3).index_select(3, edge.cells)  # (B, h, d, P)
    keys = key.flatten(3).index_select(3, edge.keys).view(
        batch, heads, dims, num, slots)
    logits = (queries.unsqueeze(-1) * keys).sum(2)  # (B, h, P, k * k)
    logits = logits + rel_bias.flatten(1)[:, edge.bias]
    logits = logits.masked_fill(~edge.inside, float('-inf'))
    attn = logits.softmax(dim=-1)
    values = value.flatten(3).index_select(3, edge.keys).view(
        batch, heads, dims_v, num, slots)
    out = (attn.unsqueeze(2) * values).sum(-1)  # (B, h, d_v, P)
    full = out.new_zeros(batch, heads, dims_v, edge.size)
    full = full.index_copy(3, edge.cells, out)
    return full.view(batch, heads, dims_v, height, width)


#: Bytes of key rows one block of :func:`_attend_inner` reads: small
#: enough for a CPU core's L2 cache, where the 2 k^2 passes over the block
#: run about twice as fast (paper size, 64 channels x 200 columns: 20 rows;
#: 267 -> 145 ms for the interior, measured 2026-11-23, f7c185c).
BLOCK_BYTES = 1 << 20


def _attend_inner(query: Tensor, key: Tensor, value: Tensor,
                  rel_bias: Tensor, kernel_size: int) -> Tensor:
    """:func:`_attend_inner_block` over blocks of rows of the map on the
    CPU, in one block on other devices.

    Every output cell is computed exactly as in one block (the same
    products and sums in the same order); only the order in which cells
    are visited changes, so that each block's keys and values stay in a
    CPU core's cache across the k^2 window slots. A GPU gains nothing
    from that and pays 4 k^2 kernel launches a block (the blocks at
    paper size and batch 2 made the fusion 67,000 launches a training
    step), so it computes the interior at once.

    Returns:
        Tensor: Shape (B, heads, d_v, H - 2r, W - 2r).
    """
    reach = kernel_size // 2
    out_h = query.shape[-2] - 2 * reach
    row_bytes = key[..., 0, :].numel() * key.element_size()
    rows = max(1, BLOCK_BYTES // max(row_bytes, 1) - 2 * reach)
    if rows >= out_h or accelerator_path(query):
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

    The query is already scaled by ``1 / sqrt(d)``. Query (i, j), i in
    [r, H - r), j in [r, W - r), slot (a, c) sees key (i - r + a,
    j - r + c): for all of them at once, the block
    ``key[..., a:a + H - 2r, c:c + W - 2r]`` (a view), with the bias at
    offset (a - r, c - r), table index (a + r, c + r).

    Returns:
        Tensor: Shape (B, heads, d_v, H - 2r, W - 2r).
    """
    height, width = query.shape[-2:]
    reach = kernel_size // 2
    out_h, out_w = height - 2 * reach, width - 2 * reach
    queries = query[..., reach:reach + out_h, reach:reach + out_w]
    slots = [divmod(s, kernel_size) for s in range(kernel_size**2)]
    logits = torch.stack([(queries * key[..., a:a + out_h,
                                         c:c + out_w]).sum(2)
                          for a, c in slots],
                         dim=2)
    # The interior's offsets -r..r: the centre (2r + 1)^2 of the table,
    # slot a * k + c at table row a + r, column c + r; one addition.
    bias = rel_bias[:, reach:reach + kernel_size, reach:reach + kernel_size]
    logits = logits + bias.reshape(1, -1, kernel_size**2, 1, 1)
    attn = logits.softmax(dim=2)
    out = 0
    for slot, (a, c) in enumerate(slots):
        out = out + attn[:, :, slot:slot + 1] * value[..., a:a + out_h,
                                                      c:c + out_w]
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


def split_heads(x: Tensor, num_heads: int) -> Tensor:
    """View (B, C, H, W) as (B, heads, C / heads, H, W)."""
    batch, channels, height, width = x.shape
    return x.view(batch, num_heads, channels // num_heads, height, width)


class _CrossAttention:
    """The projections of one neighbourhood cross-attention layer (eq. 3)
    and their use: ``Proj(NA(Q(x), K(cross), V(cross)))``."""

    def _build_attention(self, query_channels: int, cross_channels: int,
                         embed_dims: int, num_heads: int, kernel_size: int,
                         border: str, out_channels: int) -> None:
        self.num_heads = num_heads
        self.kernel_size = kernel_size
        self.border = border
        self.query = nn.Conv2d(query_channels, embed_dims, 1)
        self.key = nn.Conv2d(cross_channels, embed_dims, 1)
        self.value = nn.Conv2d(cross_channels, embed_dims, 1)
        span = 2 * kernel_size - 1
        self.rel_bias = nn.Parameter(torch.zeros(num_heads, span, span))
        nn.init.trunc_normal_(self.rel_bias, std=0.02)
        self.proj = nn.Conv2d(embed_dims, out_channels, 1)

    def _attend(self, x: Tensor, cross: Tensor) -> Tensor:
        """Attended cross features of every cell of ``x``.

        Returns:
            Tensor: Shape (B, out_channels, H, W).
        """
        attended = neighborhood_attention(
            split_heads(self.query(x), self.num_heads),
            split_heads(self.key(cross), self.num_heads),
            split_heads(self.value(cross), self.num_heads), self.rel_bias,
            self.kernel_size, self.border)
        return self.proj(attended.flatten(1, 2))


@MODELS.register_module()
class NeighborhoodFusion(_CrossAttention, BaseModule):
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
        num_layers (int): Attention layers. The first attends from the
            source; each further one (:class:`NeighborhoodCrossLayer`)
            attends from the previous layer's output to the same cross
            BEV, with its own projections and a residual connection, before
            the mix and the gate. The paper does not say how many; the
            authors' release stacks three (``depth=3`` of its NAT block).
            Defaults to 1, the module as it was (its state dict unchanged).
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
                 num_layers: int = 1,
                 init_cfg: Optional[dict] = None):
        super().__init__(init_cfg=init_cfg)
        if int(num_layers) < 1:
            raise ValueError(f'NeighborhoodFusion num_layers must be >= 1, '
                             f'got {num_layers}')
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
        self._build_attention(source_channels, cross_channels, embed_dims,
                              num_heads, kernel_size, border, out_channels)
        self.refine = nn.ModuleList(
            NeighborhoodCrossLayer(out_channels, cross_channels, embed_dims,
                                   num_heads, kernel_size, border)
            for _ in range(int(num_layers) - 1))
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
        attended = self._attend(source, cross)
        for layer in self.refine:
            attended = layer(attended, cross)
        fused = self.mix(torch.cat([source, attended], dim=1))
        return fused * self.gate(fused)


class NeighborhoodCrossLayer(_CrossAttention, nn.Module):
    """A further neighbourhood cross-attention layer of
    :class:`NeighborhoodFusion`: ``x + Proj(NA(Q(x), K(cross), V(cross)))``
    (eq. 3 from the previous layer's output, with a residual connection).

    Args:
        channels (int): Channels of ``x`` (and of the output).
        cross_channels (int): Channels of the cross BEV (keys, values).
        embed_dims (int): Attention width, split over the heads.
        num_heads (int): Attention heads.
        kernel_size (int): Neighbourhood size k.
        border (str): One of :data:`BORDERS`.
    """

    def __init__(self, channels: int, cross_channels: int, embed_dims: int,
                 num_heads: int, kernel_size: int, border: str) -> None:
        super().__init__()
        self._build_attention(channels, cross_channels, embed_dims,
                              num_heads, kernel_size, border, channels)

    def forward(self, x: Tensor, cross: Tensor) -> Tensor:
        """Attend from ``x`` (B, C, H, W) to ``cross`` (B, C_c, H, W).

        Returns:
            Tensor: Shape (B, C, H, W).
        """
        return x + self._attend(x, cross)
