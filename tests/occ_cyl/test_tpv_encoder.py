"""Tests of the shared Swin + FPN plane encoder (eqs. 14-16)."""
import pytest
import torch
from mmdet3d.utils import register_all_modules

from projects.occ_cyl import TPVPlaneEncoder

register_all_modules(init_default_scope=False)


def _encoder():
    torch.manual_seed(0)
    return TPVPlaneEncoder(
        backbone=dict(
            type='mmdet.SwinTransformer',
            in_channels=4,
            embed_dims=8,
            depths=(1, 1),
            num_heads=(1, 1),
            window_size=2,
            patch_size=1,
            strides=(1, 2),
            out_indices=(0, 1),
            pretrain_img_size=8),
        neck=dict(
            type='mmdet.FPN', in_channels=[8, 16], out_channels=6,
            num_outs=2))


def test_shared_weights_and_scales():
    """Planes (8, 8), (8, 4), (8, 2) give per level 0 the same sizes and per
    level 1 half of them (ceil): (4, 4), (4, 2), (4, 1). Each plane's output
    equals running the shared backbone and neck on it alone."""
    enc = _encoder().eval()
    gen = torch.Generator().manual_seed(0)
    planes = [torch.randn(2, 4, 8, w, generator=gen) for w in (8, 4, 2)]
    out = enc(planes)
    assert len(out) == 2
    assert [tuple(p.shape) for p in out[0]] == [(2, 6, 8, 8), (2, 6, 8, 4),
                                                (2, 6, 8, 2)]
    assert [tuple(p.shape) for p in out[1]] == [(2, 6, 4, 4), (2, 6, 4, 2),
                                                (2, 6, 4, 1)]
    alone = enc.neck(enc.backbone(planes[1]))
    torch.testing.assert_close(out[0][1], alone[0])
    torch.testing.assert_close(out[1][1], alone[1])


def test_backward_and_errors():
    """Every plane gets gradient through the shared weights; two planes are
    refused."""
    enc = _encoder()
    planes = [torch.randn(1, 4, 8, w, requires_grad=True) for w in (8, 4, 2)]
    sum(p.sum() for lvl in enc(planes) for p in lvl).backward()
    assert all(p.grad.abs().sum() > 0 for p in planes)
    with pytest.raises(ValueError, match='three planes'):
        enc(planes[:2])
