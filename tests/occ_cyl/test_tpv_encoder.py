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


def _paper_like_swin(in_channels=4):
    """Patch 2 and three stride-2 merges, as the paper config: level
    strides 2, 4, 8, 16."""
    torch.manual_seed(0)
    return TPVPlaneEncoder(
        backbone=dict(
            type='mmdet.SwinTransformer',
            in_channels=in_channels,
            embed_dims=4,
            depths=(1, 1, 1, 1),
            num_heads=(1, 1, 1, 1),
            window_size=2,
            patch_size=2,
            strides=(2, 2, 2, 2),
            out_indices=(0, 1, 2, 3),
            pretrain_img_size=16),
        neck=dict(
            type='mmdet.FPN', in_channels=[4, 8, 16, 32], out_channels=4,
            num_outs=4))


def test_every_level_covers_exactly_the_plane():
    """Issue 11, item 6. Level strides 2, 4, 8, 16. A 32 x 16 plane gives
    levels of 16 x 8, 8 x 4, 4 x 2 and 2 x 1 cells: cells x stride =
    32 x 16 at every level, so one normalised coordinate means the same
    place on every level."""
    enc = _paper_like_swin().eval()
    assert enc.level_strides == (2, 4, 8, 16)
    enc.check_plane_shape((32, 16), '(R, Theta)')
    with torch.no_grad():
        out = enc([torch.randn(1, 4, 32, 16)] * 3)
    shapes = [tuple(level[0].shape[-2:]) for level in out]
    assert shapes == [(16, 8), (8, 4), (4, 2), (2, 1)]
    assert all((h * s, w * s) == (32, 16)
               for (h, w), s in zip(shapes, enc.level_strides))


def test_a_plane_a_level_would_pad_is_refused():
    """A 40-cell side (PointOcc's 360 azimuth cells scaled down: not a
    multiple of 16): level 3 would have ceil(40 / 16) = 3 cells covering
    48, mmdet's Swin pads 8 cells at the end and the head would sample
    that level 8 cells out of register. check_plane_shape names the plane,
    the level and the extent; forward refuses such a plane too."""
    enc = _paper_like_swin().eval()
    with pytest.raises(ValueError, match=r'\(Theta, Z\) plane \(40, 16\).*'
                       r'level 3.*stride 16.*cover 48 cells'):
        enc.check_plane_shape((40, 16), '(Theta, Z)')
    with torch.no_grad(), pytest.raises(ValueError,
                                        match=r'level 3 of plane 0 covers '
                                        r'\(48, 16\) cells'):
        enc([torch.randn(1, 4, 40, 16)] * 3)


def test_backbone_without_strides_is_refused():
    """The level strides come from the config; a backbone config without
    strides and out_indices is named."""
    with pytest.raises(ValueError, match='strides and out_indices'):
        TPVPlaneEncoder(
            backbone=dict(type='mmdet.SwinTransformer', in_channels=4),
            neck=dict(type='mmdet.FPN', in_channels=[96], out_channels=4,
                      num_outs=1))
