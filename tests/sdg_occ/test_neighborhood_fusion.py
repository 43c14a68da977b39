"""Tests of neighbourhood attention and ``NeighborhoodFusion``."""
import math

import pytest
import torch

from projects.sdg_occ import NeighborhoodFusion, neighborhood_attention
from projects.sdg_occ import neighborhood_fusion as nf
from projects.sdg_occ.neighborhood_fusion import window_starts


def _window(i, length, ksize, border):
    """Window rows (or columns) of query i, written as NAT describes it.

    'shift': a centred window, moved inside the map where it would cross
    the border (NATTEN: start 0 near the start, length - k near the end).
    'mask': the centred window, cells outside the map removed.
    """
    r = ksize // 2
    if border == 'mask':
        return [p for p in range(i - r, i + r + 1) if 0 <= p < length]
    if i < r:
        start = 0
    elif i + r >= length:
        start = length - ksize
    else:
        start = i - r
    return list(range(start, start + ksize))


def _naive_attention(q, k, v, bias, ksize, border):
    """Per-query loop over the keys of the window; the bias of key (p, q')
    for query (i, j) is bias[h, p - i + k - 1, q' - j + k - 1]."""
    batch, heads, dims, height, width = q.shape
    out = torch.zeros(batch, heads, v.shape[2], height, width)
    for b in range(batch):
        for h in range(heads):
            for i in range(height):
                for j in range(width):
                    logits, values = [], []
                    for p in _window(i, height, ksize, border):
                        for q_ in _window(j, width, ksize, border):
                            logit = (q[b, h, :, i, j] * k[b, h, :, p, q_]
                                     ).sum() / math.sqrt(dims)
                            logits.append(logit + bias[h, p - i + ksize - 1,
                                                       q_ - j + ksize - 1])
                            values.append(v[b, h, :, p, q_])
                    attn = torch.softmax(torch.stack(logits), dim=0)
                    out[b, h, :, i, j] = (attn[:, None] *
                                          torch.stack(values)).sum(0)
    return out


@pytest.mark.parametrize('border', ['shift', 'mask'])
@pytest.mark.parametrize('ksize', [1, 3, 5])
def test_matches_naive_per_query_loop(ksize, border):
    """A 6 x 7 map is larger than every window, so border and interior
    queries both occur; the bias table is random."""
    gen = torch.Generator().manual_seed(ksize)
    q = torch.randn(2, 2, 3, 6, 7, generator=gen)
    k = torch.randn(2, 2, 3, 6, 7, generator=gen)
    v = torch.randn(2, 2, 2, 6, 7, generator=gen)
    bias = torch.randn(2, 2 * ksize - 1, 2 * ksize - 1, generator=gen)
    out = neighborhood_attention(q, k, v, bias, ksize, border)
    ref = _naive_attention(q, k, v, bias, ksize, border)
    assert torch.allclose(out, ref, atol=1e-5)


@pytest.mark.parametrize('border', ['shift', 'mask'])
def test_row_blocks_match_naive_loop_and_gradients(border, monkeypatch):
    """Interior rows split into blocks give the per-query loop's output and
    the single-block gradients of q, k, v and the bias. A key row holds
    1 x 2 x 3 x 4 floats = 96 bytes and a block needs 2 r = 2 rows of
    margin, so budgets of 1, 4 x 96 and 6 x 96 bytes give blocks of 1, 2
    and 4 output rows over the 9 - 2 = 7 interior rows."""
    gen = torch.Generator().manual_seed(3)
    q, k, v = (torch.randn(1, 2, 3, 9, 4, generator=gen).requires_grad_()
               for _ in range(3))
    bias = torch.randn(2, 5, 5, generator=gen).requires_grad_()
    ref = _naive_attention(q.detach(), k.detach(), v.detach(),
                           bias.detach(), 3, border)
    whole = neighborhood_attention(q, k, v, bias, 3, border)
    grad_out = torch.randn_like(whole)
    grads = torch.autograd.grad(whole, (q, k, v, bias), grad_out)
    for budget in (1, 4 * 96, 6 * 96):
        monkeypatch.setattr(nf, 'BLOCK_BYTES', budget)
        out = neighborhood_attention(q, k, v, bias, 3, border)
        assert torch.allclose(out, ref, atol=1e-5)
        for got, want in zip(
                torch.autograd.grad(out, (q, k, v, bias), grad_out), grads):
            assert torch.allclose(got, want, atol=1e-5)


def _key_count(height, width, ksize, border, query):
    """Keys a query attends to, read from the output: with zero queries,
    keys and bias the attention is uniform, 1 / n over its n keys, so with
    a value of 1 at the query's own cell and 0 elsewhere the output there
    is 1 / n."""
    zeros = torch.zeros(1, 1, 1, height, width)
    value = torch.zeros(1, 1, 1, height, width)
    value[..., query[0], query[1]] = 1.0
    bias = torch.zeros(1, 2 * ksize - 1, 2 * ksize - 1)
    out = neighborhood_attention(zeros, zeros, value, bias, ksize, border)
    return round(1.0 / out[0, 0, 0, query[0], query[1]].item())


def test_border_queries_see_k_squared_keys_when_shifted():
    """k = 7 on a 10 x 12 map. Shifted (NAT): the corner (0, 0), the edge
    cell (0, 5) and the interior (5, 6) each see 7 * 7 = 49 keys. Masked:
    the corner sees rows 0..3 x columns 0..3 = 16, the edge rows 0..3 x
    columns 2..8 = 28, the interior 49."""
    for query, shifted, masked in (((0, 0), 49, 16), ((0, 5), 49, 28),
                                   ((5, 6), 49, 49)):
        assert _key_count(10, 12, 7, 'shift', query) == shifted
        assert _key_count(10, 12, 7, 'mask', query) == masked


def test_window_starts_by_hand():
    """k = 3 on 5 cells: shifted starts 0, 0, 1, 2, 2 (the windows 0-2,
    0-2, 1-3, 2-4, 2-4); masked -1, 0, 1, 2, 3. A map of 2 cells is smaller
    than the window: it starts at 0 and the third row is masked."""
    assert window_starts(5, 3, 'shift').tolist() == [0, 0, 1, 2, 2]
    assert window_starts(5, 3, 'mask').tolist() == [-1, 0, 1, 2, 3]
    assert window_starts(2, 3, 'shift').tolist() == [0, 0]
    assert _key_count(2, 2, 3, 'shift', (0, 0)) == 4


def test_by_hand_uniform_keys_and_shifted_bias():
    """1 x 3 map, values (1, 2, 4), k = 3 (the map is one row: rows beyond
    it are masked in both modes).

    Shifted windows: every query sees the 3 cells -> 7/3 each. Masked: the
    left cell averages (1, 2) -> 1.5, the middle 7/3, the right (2, 4) ->
    3. A bias of ln 2 at column offset +2 (table column 2 + 2 = 4) doubles
    the weight of the key two cells to the right, which only the shifted
    window of the left query reaches: left -> (1 + 2 + 2*4) / 4 = 2.75.
    """
    q = torch.zeros(1, 1, 1, 1, 3)
    k = torch.zeros(1, 1, 1, 1, 3)
    v = torch.tensor([1.0, 2.0, 4.0]).view(1, 1, 1, 1, 3)
    bias = torch.zeros(1, 5, 5)
    out = neighborhood_attention(q, k, v, bias, 3, 'shift')
    assert torch.allclose(out.flatten(), torch.full((3, ), 7 / 3))
    out = neighborhood_attention(q, k, v, bias, 3, 'mask')
    assert torch.allclose(out.flatten(), torch.tensor([1.5, 7 / 3, 3.0]))
    bias[0, 2, 4] = math.log(2.0)
    out = neighborhood_attention(q, k, v, bias, 3, 'shift')
    assert torch.allclose(out.flatten(), torch.tensor([2.75, 7 / 3, 7 / 3]))


def test_fusion_forward_backward_and_gate_range():
    """Output shape, gradients into both inputs and every parameter."""
    torch.manual_seed(0)
    fusion = NeighborhoodFusion(
        source_channels=6, cross_channels=4, out_channels=5, embed_dims=8,
        num_heads=2, kernel_size=3)
    source = torch.randn(2, 6, 8, 8, requires_grad=True)
    cross = torch.randn(2, 4, 8, 8, requires_grad=True)
    out = fusion(source, cross)
    assert out.shape == (2, 5, 8, 8)
    # The mix ends in a ReLU and the gate is a sigmoid: output >= 0.
    assert (out >= 0).all()
    out.pow(2).mean().backward()
    assert source.grad.abs().sum() > 0 and cross.grad.abs().sum() > 0
    assert fusion.rel_bias.grad is not None
    assert fusion.rel_bias.shape == (2, 5, 5)


def test_stacked_layers_refine_the_attended_features():
    """num_layers=3 (the authors' release stacks three): the first layer's
    parameters keep their names (a one-layer state dict is a subset), two
    further layers attend from the previous output with their own
    projections; with the further layers' output projections at zero they
    add nothing (their residual passes the first layer's output on), so
    the output is the one-layer module's exactly, and otherwise it
    differs and every further parameter gets a gradient."""
    torch.manual_seed(0)
    one = NeighborhoodFusion(6, 4, 5, embed_dims=8, num_heads=2,
                             kernel_size=3)
    three = NeighborhoodFusion(6, 4, 5, embed_dims=8, num_heads=2,
                               kernel_size=3, num_layers=3)
    assert set(one.state_dict()) < set(three.state_dict())
    assert len(three.refine) == 2
    three.load_state_dict(one.state_dict(), strict=False)
    for layer in three.refine:
        torch.nn.init.zeros_(layer.proj.weight)
        torch.nn.init.zeros_(layer.proj.bias)
    source, cross = torch.randn(2, 6, 8, 8), torch.randn(2, 4, 8, 8)
    torch.testing.assert_close(three(source, cross), one(source, cross))
    for layer in three.refine:
        torch.nn.init.normal_(layer.proj.weight)
    out = three(source, cross)
    assert not torch.allclose(out, one(source, cross))
    out.pow(2).mean().backward()
    for name, param in three.refine.named_parameters():
        assert param.grad is not None and param.grad.abs().sum() > 0, name
    with pytest.raises(ValueError, match='num_layers'):
        NeighborhoodFusion(6, 4, 5, embed_dims=8, num_heads=2, num_layers=0)


def test_fusion_empty_batch():
    fusion = NeighborhoodFusion(3, 3, 3, embed_dims=4, num_heads=2,
                                kernel_size=3).eval()
    out = fusion(torch.zeros(0, 3, 4, 4), torch.zeros(0, 3, 4, 4))
    assert out.shape == (0, 3, 4, 4)


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match='odd'):
        NeighborhoodFusion(4, 4, 4, embed_dims=4, num_heads=1, kernel_size=4)
    with pytest.raises(ValueError, match='divisible'):
        NeighborhoodFusion(4, 4, 4, embed_dims=6, num_heads=4)
    fusion = NeighborhoodFusion(4, 4, 4, embed_dims=4, num_heads=1,
                                kernel_size=3)
    with pytest.raises(ValueError, match='same grid'):
        fusion(torch.zeros(1, 4, 4, 4), torch.zeros(1, 4, 4, 5))
    with pytest.raises(ValueError, match='rel_bias'):
        neighborhood_attention(
            torch.zeros(1, 1, 1, 2, 2), torch.zeros(1, 1, 1, 2, 2),
            torch.zeros(1, 1, 1, 2, 2), torch.zeros(1, 9), 3)
    with pytest.raises(ValueError, match='border'):
        NeighborhoodFusion(4, 4, 4, embed_dims=4, num_heads=1,
                           border='clamp')
    with pytest.raises(ValueError, match='4 source'):
        fusion(torch.zeros(1, 3, 4, 4), torch.zeros(1, 4, 4, 4))


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs CUDA')
def test_cuda_matches_cpu():
    gen = torch.Generator().manual_seed(0)
    q, k, v = (torch.randn(1, 2, 4, 6, 7, generator=gen) for _ in range(3))
    bias = torch.randn(2, 9, 9, generator=gen)
    ref = neighborhood_attention(q, k, v, bias, 5)
    out = neighborhood_attention(q.cuda(), k.cuda(), v.cuda(), bias.cuda(), 5)
    assert torch.allclose(out.cpu(), ref, atol=1e-5)


def _strip_attention(q, k, v, bias, ksize, border):
    """The border handling before issue 46, kept as the reference of the
    gathered border cells: four strips, each a Python loop over the k * k
    window slots with two ``index_select`` a slot; the interior by the
    per-slot views (which the rewrite keeps)."""
    height, width = q.shape[-2:]
    reach = ksize // 2
    scale = 1.0 / math.sqrt(q.shape[2])

    def strip(rows, cols):
        rows, cols = torch.arange(*rows), torch.arange(*cols)
        queries = q.index_select(3, rows).index_select(4, cols)
        key_rows, row_in, bias_rows = nf._window_slots(height, ksize, border,
                                                       rows)
        key_cols, col_in, bias_cols = nf._window_slots(width, ksize, border,
                                                       cols)
        logits = []
        for a in range(ksize):
            keys_a = k.index_select(3, key_rows[a])
            bias_a = bias[:, bias_rows[a]]
            for c in range(ksize):
                logit = (queries * keys_a.index_select(4, key_cols[c])).sum(2)
                logit = logit * scale + bias_a[:, :, bias_cols[c]]
                inside = row_in[a].view(-1, 1) & col_in[c].view(1, -1)
                logits.append(logit.masked_fill(~inside, float('-inf')))
        attn = torch.stack(logits, dim=2).softmax(dim=2)
        out = 0
        for a in range(ksize):
            values_a = v.index_select(3, key_rows[a])
            for c in range(ksize):
                out = out + attn[:, :, a * ksize + c:a * ksize + c + 1] * \
                    values_a.index_select(4, key_cols[c])
        return out

    inner = nf._attend_inner(q * scale, k, v, bias, ksize)
    middle = torch.cat([
        strip((reach, height - reach), (0, reach)), inner,
        strip((reach, height - reach), (width - reach, width))
    ], dim=4)
    return torch.cat([
        strip((0, reach), (0, width)), middle,
        strip((height - reach, height), (0, width))
    ], dim=3)


@pytest.mark.parametrize('border', ['shift', 'mask'])
def test_gathered_border_matches_the_strips_it_replaces(border):
    """SDG-OCC's k = 7 on a 17 x 19 map, batch 2: the border cells'
    one-gather path gives the previous strips' values and the gradients of
    q, k, v and the bias table, within float rounding."""
    gen = torch.Generator().manual_seed(7)
    q, k, v = (torch.randn(2, 4, 8, 17, 19, generator=gen).requires_grad_()
               for _ in range(3))
    bias = torch.randn(4, 13, 13, generator=gen).requires_grad_()
    new = neighborhood_attention(q, k, v, bias, 7, border)
    old = _strip_attention(q, k, v, bias, 7, border)
    assert torch.allclose(new, old, atol=1e-5)
    grad_out = torch.randn_like(new)
    for got, want in zip(
            torch.autograd.grad(new, (q, k, v, bias), grad_out),
            torch.autograd.grad(old, (q, k, v, bias), grad_out)):
        assert torch.allclose(got, want, atol=1e-5)


def test_launches_do_not_grow_with_the_batch():
    """Off the CPU's row blocks (what a GPU runs), the attention's
    operator count is the same at batch 1 and batch 4: the border cells
    are one gather, the interior one pass of k * k slots, and no call
    after the first (which builds the border indices of the map shape)
    waits for the device. Counted on the path a GPU takes (no row
    blocks), forced on the CPU."""
    from projects.occ_common.analysis.op_counting import OpCounter
    from projects.occ_common.utils.device_path import forced_accelerator_path
    counts = []
    for batch in (1, 4):
        module = NeighborhoodFusion(8, 8, 8, embed_dims=8, num_heads=2)
        source, cross = torch.randn(2, batch, 8, 40, 40)
        with torch.no_grad():
            module(source, cross)  # the border indices, once per shape
        counter = OpCounter(torch.nn.Sequential(module))
        with torch.no_grad(), forced_accelerator_path(), counter:
            module(source, cross)
        counts.append(counter.totals())
    assert counts[0] == counts[1]
    assert counts[0]['syncs'] == 0
    # 49 slot products (mul, sum) and 49 weighted values (mul, add) make
    # ~200 of them; the border, the projections and the gate ~40.
    assert counts[0]['launches'] < 260


@pytest.mark.parametrize('kernel_size', [3, 5])
def test_border_cells_are_the_cells_outside_the_interior(kernel_size):
    """The border cells come from a sort with a count fixed by the shape
    (what compiled code traces), no longer from ``nonzero``; they are
    still every cell within ``k // 2`` of an edge, in row-major order, and
    every cell when the map has no interior: checked against a direct
    listing on maps from 1 x 1 to 7 x 6 (a 5 x 5 map with k = 5 has the
    single interior cell (2, 2), so 24 border cells)."""
    reach = kernel_size // 2
    for height in range(1, 8):
        for width in range(1, 7):
            edge = nf._border_cells(height, width, kernel_size, 'shift',
                                    'cpu')
            interior = height > 2 * reach and width > 2 * reach
            expected = [
                i * width + j for i in range(height) for j in range(width)
                if not interior or min(i, j) < reach
                or i >= height - reach or j >= width - reach
            ]
            assert edge.cells.tolist() == expected, (height, width)
            assert edge.interior == interior
    assert nf._border_cells(5, 5, 5, 'shift', 'cpu').cells.numel() == 24
