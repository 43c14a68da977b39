"""Tests of ``SDGBEVEncoder``."""
import pytest
import torch

from projects.sdg_occ import SDGBEVEncoder


@pytest.mark.parametrize('size', [(8, 8), (7, 9)])
def test_output_at_input_resolution_and_backward(size):
    """Strides 2, 4, 8 and back: (8, 8) -> 4, 2, 1 -> (8, 8); odd sizes
    (7, 9) -> 4x5, 2x3, 1x2 still come back to (7, 9)."""
    torch.manual_seed(0)
    enc = SDGBEVEncoder(
        in_channels=3, stage_channels=(4, 6, 8), num_blocks=(1, 2, 1),
        out_channels=5)
    x = torch.randn(2, 3, *size, requires_grad=True)
    out = enc(x)
    assert out.shape == (2, 5, *size)
    out.mean().backward()
    assert x.grad.abs().sum() > 0
    assert all(p.grad is not None for p in enc.parameters())


def test_stage_count_and_empty_batch():
    enc = SDGBEVEncoder(3, stage_channels=(4, 8), num_blocks=(1, 1),
                        out_channels=2).eval()
    assert len(enc.stages) == 2 and len(enc.merges) == 1
    assert enc(torch.zeros(0, 3, 8, 8)).shape == (0, 2, 8, 8)


def test_bad_config_raises():
    with pytest.raises(ValueError, match='num_blocks'):
        SDGBEVEncoder(3, stage_channels=(4, 8), num_blocks=(1, ))
    with pytest.raises(ValueError, match='>= 1'):
        SDGBEVEncoder(3, stage_channels=(4, 8), num_blocks=(1, 0))
    with pytest.raises(ValueError, match=r'\(B, C, Y, X\)'):
        SDGBEVEncoder(3, (4, ), (1, ))(torch.zeros(3, 8, 8))
