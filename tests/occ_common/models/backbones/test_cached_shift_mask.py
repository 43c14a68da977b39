"""Swin's shifted-window attention with the shift mask built once per map
shape gives mmdet's outputs and gradients."""
import copy

import pytest
import torch
from mmdet.models.backbones.swin import ShiftWindowMSA

from projects.occ_common.models.backbones.cached_shift_mask import (
    CachedMaskShiftWindowMSA, cache_shift_masks)


@pytest.mark.parametrize('shift, hw', [(0, (7, 7)), (3, (7, 7)),
                                       (3, (9, 12)), (2, (5, 4))])
def test_equals_mmdets_attention(shift, hw):
    """Window 7 (4 for the last case): unpadded, shifted, and padded maps
    (9 x 12 pads to 14 x 14)."""
    torch.manual_seed(0)
    window = 4 if hw == (5, 4) else 7
    theirs = ShiftWindowMSA(8, 2, window, shift_size=shift).eval()
    ours = copy.deepcopy(theirs)
    assert cache_shift_masks(ours) == 1
    assert isinstance(ours, CachedMaskShiftWindowMSA)
    x = torch.randn(2, hw[0] * hw[1], 8, requires_grad=True)
    want = theirs(x, hw)
    grad_out = torch.randn_like(want)
    want_grads = torch.autograd.grad(want, [x, *theirs.parameters()],
                                     grad_out)
    for _ in range(2):  # the second call reads the cached mask
        got = ours(x, hw)
        assert torch.allclose(got, want, atol=1e-6)
        for a, b in zip(torch.autograd.grad(got, [x, *ours.parameters()],
                                            grad_out), want_grads):
            assert torch.allclose(a, b, atol=1e-6)
    assert len(ours.__dict__.get('_shift_masks', {})) == (1 if shift else 0)


def test_recomputed_swin_uses_it():
    """Every block's attention of the project's Swin is switched; the
    state dict keeps mmdet's names."""
    from projects.occ_common.models.backbones import RecomputedSwinTransformer
    swin = RecomputedSwinTransformer(embed_dims=8, depths=(2, 2),
                                     num_heads=(1, 2), window_size=4,
                                     out_indices=(0, 1))
    kinds = {type(m) for m in swin.modules()
             if isinstance(m, ShiftWindowMSA)}
    assert kinds == {CachedMaskShiftWindowMSA}
    assert 'stages.0.blocks.1.attn.w_msa.qkv.weight' in swin.state_dict()
