"""Tests of the multi-view image encoder."""
import torch

from projects.occ_common.testing.autograd_memory import saved_tensor_bytes
from projects.occ_cyl import MultiViewImageEncoder


def _encoder(**kwargs):
    torch.manual_seed(0)
    return MultiViewImageEncoder(
        # As the paper's: frozen stage 1 and statistics, checkpointed.
        backbone=dict(
            type='mmdet.ResNet', depth=18, base_channels=4,
            out_indices=(0, 1, 2, 3), frozen_stages=1, norm_eval=True,
            with_cp=True),
        neck=dict(
            type='mmdet.FPN', in_channels=[4, 8, 16, 32], out_channels=8,
            num_outs=4),
        neck_channels=8,
        num_levels=4,
        out_channels=6,
        **kwargs).double().train()


def test_checkpointed_neck_keeps_values_and_gradients():
    """``with_cp`` recomputes the FPN and the resizing in the backward:
    bitwise the same ``V``, running statistics and gradients (to every
    parameter) on two 64 x 96 views, and far less kept for the backward
    (the 1/4 FPN level and its sums are no longer saved). Without a
    gradient nothing is checkpointed."""
    gen = torch.Generator().manual_seed(1)
    imgs = torch.randn(1, 2, 3, 64, 96, generator=gen, dtype=torch.float64)
    weight = torch.randn(2, 6, 4, 6, generator=gen, dtype=torch.float64)
    results = {}
    for with_cp in (False, True):
        encoder = _encoder(with_cp=with_cp)
        out, saved = saved_tensor_bytes(lambda: encoder(imgs))
        (out * weight).sum().backward()
        grads = [p.grad for p in encoder.parameters() if p.requires_grad]
        results[with_cp] = (out, grads, list(encoder.buffers()), saved)
    plain, cp = results[False], results[True]
    assert plain[0].shape == (2, 6, 4, 6)
    assert torch.equal(plain[0], cp[0])
    assert all(torch.equal(a, b) for a, b in zip(plain[1], cp[1]))
    assert all(torch.equal(a, b) for a, b in zip(plain[2], cp[2]))
    assert cp[3] < 0.7 * plain[3]
    with torch.no_grad():
        assert torch.equal(_encoder(with_cp=True).eval()(imgs),
                           _encoder().eval()(imgs))
