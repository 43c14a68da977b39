"""Tests of neighbourhood attention and ``NeighborhoodFusion``."""
import math

import pytest
import torch

from projects.sdg_occ import NeighborhoodFusion, neighborhood_attention


def _naive_attention(q, k, v, bias, ksize):
    """Per-pixel loop: softmax over the in-map cells of the centred window.

    Window slot s = a * ksize + b holds offset (a - r, b - r), r = ksize//2.
    """
    batch, heads, dims, height, width = q.shape
    r = ksize // 2
    out = torch.zeros(batch, heads, v.shape[2], height, width)
    for b in range(batch):
        for h in range(heads):
            for i in range(height):
                for j in range(width):
                    logits, values = [], []
                    for a in range(ksize):
                        for c in range(ksize):
                            p, q_ = i + a - r, j + c - r
                            if not (0 <= p < height and 0 <= q_ < width):
                                continue
                            logit = (q[b, h, :, i, j] * k[b, h, :, p, q_]
                                     ).sum() / math.sqrt(dims)
                            logits.append(logit + bias[h, a * ksize + c])
                            values.append(v[b, h, :, p, q_])
                    attn = torch.softmax(torch.stack(logits), dim=0)
                    out[b, h, :, i, j] = (attn[:, None] *
                                          torch.stack(values)).sum(0)
    return out


@pytest.mark.parametrize('ksize', [1, 3, 5])
def test_matches_naive_per_pixel_loop(ksize):
    gen = torch.Generator().manual_seed(ksize)
    q = torch.randn(2, 2, 3, 4, 5, generator=gen)
    k = torch.randn(2, 2, 3, 4, 5, generator=gen)
    v = torch.randn(2, 2, 2, 4, 5, generator=gen)
    bias = torch.randn(2, ksize * ksize, generator=gen)
    out = neighborhood_attention(q, k, v, bias, ksize)
    ref = _naive_attention(q, k, v, bias, ksize)
    assert torch.allclose(out, ref, atol=1e-5)


def test_by_hand_uniform_keys():
    """Zero queries and zero bias give uniform weights over in-map cells.

    1 x 3 map, values (1, 2, 4), k = 3: the left cell averages (1, 2) ->
    1.5, the middle (1, 2, 4) -> 7/3, the right (2, 4) -> 3; a bias of
    ln 2 on the right neighbour slot (a=1, c=2 -> slot 5) doubles its
    weight: middle -> (1 + 2 + 2*4) / 4 = 2.75, left -> (1 + 2*2) / 3.
    """
    q = torch.zeros(1, 1, 1, 1, 3)
    k = torch.zeros(1, 1, 1, 1, 3)
    v = torch.tensor([1.0, 2.0, 4.0]).view(1, 1, 1, 1, 3)
    out = neighborhood_attention(q, k, v, torch.zeros(1, 9), 3)
    assert torch.allclose(out.flatten(), torch.tensor([1.5, 7 / 3, 3.0]))
    bias = torch.zeros(1, 9)
    bias[0, 5] = math.log(2.0)
    out = neighborhood_attention(q, k, v, bias, 3)
    assert torch.allclose(out.flatten(), torch.tensor([5 / 3, 2.75, 3.0]))


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
    assert fusion.rel_bias.shape == (2, 9)


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
            torch.zeros(1, 1, 1, 2, 2), torch.zeros(1, 4), 3)


@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs CUDA')
def test_cuda_matches_cpu():
    gen = torch.Generator().manual_seed(0)
    q, k, v = (torch.randn(1, 2, 4, 6, 7, generator=gen) for _ in range(3))
    bias = torch.randn(2, 25, generator=gen)
    ref = neighborhood_attention(q, k, v, bias, 5)
    out = neighborhood_attention(q.cuda(), k.cuda(), v.cuda(), bias.cuda(), 5)
    assert torch.allclose(out.cpu(), ref, atol=1e-5)
