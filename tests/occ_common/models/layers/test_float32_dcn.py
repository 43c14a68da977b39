"""Float32DCNv2: mmcv's DCNv2 trains under bfloat16 autocast (issue 47's
DCN stages in OccCylindrical's ResNet)."""
import pytest
import torch
from mmcv.ops import ModulatedDeformConv2dPack

from projects.occ_common.models.layers import Float32DCNv2


def _pair():
    torch.manual_seed(0)
    plain = ModulatedDeformConv2dPack(4, 6, 3, padding=1)
    # Non-zero offsets and masks, so the deformable sampling is exercised.
    torch.nn.init.normal_(plain.conv_offset.weight, std=0.1)
    island = Float32DCNv2(4, 6, 3, padding=1)
    island.load_state_dict(plain.state_dict())
    return plain, island


def test_bfloat16_autocast_runs_in_float32():
    """mmcv's layer raises under CPU bfloat16 autocast (its kernel has no
    bfloat16); the island returns float32 equal to mmcv's layer run in
    float32 on the same (bfloat16-rounded) input, and its gradients reach
    the input and every weight."""
    plain, island = _pair()
    x = torch.randn(2, 4, 8, 8).bfloat16().float().requires_grad_()
    with torch.autocast('cpu', dtype=torch.bfloat16):
        with pytest.raises(NotImplementedError, match='BFloat16'):
            plain(x.bfloat16())
        out = island(x.bfloat16())
    assert out.dtype == torch.float32
    torch.testing.assert_close(out, plain(x), rtol=0, atol=0)
    out.sum().backward()
    assert x.grad is not None and bool(x.grad.abs().sum() > 0)
    for name, param in island.named_parameters():
        assert param.grad is not None and bool(param.grad.abs().sum() > 0), \
            name


def test_without_autocast_it_is_mmcvs_layer():
    """Same state dict keys and, in float32 without autocast, the same
    output to the bit."""
    plain, island = _pair()
    assert island.state_dict().keys() == plain.state_dict().keys()
    x = torch.randn(1, 4, 8, 8)
    torch.testing.assert_close(island(x), plain(x), rtol=0, atol=0)
