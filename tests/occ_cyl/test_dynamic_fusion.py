"""Tests of the OccFusion-style 2D dynamic fusion."""
import pytest
import torch

from projects.occ_cyl import DynamicFusion2D


def test_output_is_the_gated_fused_plane():
    """out = F * sigmoid(W @ mean_hw(F) + b) with F = conv(cat(cam, lidar)):
    recomputed from the module's layers, and with the gate zeroed
    (W = 0, b = 0) every channel is exactly F / 2 (sigmoid(0) = 0.5)."""
    torch.manual_seed(0)
    fusion = DynamicFusion2D((3, 2), 4).eval()
    cam, lidar = torch.randn(2, 3, 5, 6), torch.randn(2, 2, 5, 6)
    out = fusion(cam, lidar)
    fused = fusion.fuse(torch.cat([cam, lidar], 1))
    gate = torch.sigmoid(fusion.gate[1](fused.mean(dim=(2, 3),
                                                   keepdim=True)))
    torch.testing.assert_close(out, fused * gate)
    torch.nn.init.zeros_(fusion.gate[1].weight)
    torch.nn.init.zeros_(fusion.gate[1].bias)
    torch.testing.assert_close(fusion(cam, lidar), fused / 2)


def test_backward_reaches_both_inputs_and_empty_batch():
    """Both modalities receive gradient; a zero-sized batch passes."""
    fusion = DynamicFusion2D((3, 2), 4)
    cam = torch.randn(2, 3, 4, 4, requires_grad=True)
    lidar = torch.randn(2, 2, 4, 4, requires_grad=True)
    fusion(cam, lidar).square().sum().backward()
    assert cam.grad.abs().sum() > 0 and lidar.grad.abs().sum() > 0
    out = fusion.eval()(torch.zeros(0, 3, 4, 4), torch.zeros(0, 2, 4, 4))
    assert out.shape == (0, 4, 4, 4)


def test_mismatched_planes_raise():
    """Wrong channel counts or sizes name the expected channels."""
    fusion = DynamicFusion2D((3, 2), 4)
    with pytest.raises(ValueError, match=r'\(3, 2\)'):
        fusion(torch.zeros(1, 3, 4, 4), torch.zeros(1, 3, 4, 4))
    with pytest.raises(ValueError, match='one spatial size'):
        fusion(torch.zeros(1, 3, 4, 4), torch.zeros(1, 2, 4, 5))


def test_squeeze_excite_gate_is_occfusions():
    """gate='squeeze_excite': out = F * sigmoid(W2 relu(W1 mean_hw(F)))
    with W1 (C/2 x C) and W2 (C x C/2), no biases (OCCFusion's released
    DynamicFusion2D), recomputed by hand from the weights; 2 * 4 * 2 = 16
    gate parameters against the 'conv' gate's 4 * 4 + 4 = 20."""
    torch.manual_seed(0)
    fusion = DynamicFusion2D((3, 2), 4, gate='squeeze_excite').eval()
    cam, lidar = torch.randn(2, 3, 5, 6), torch.randn(2, 2, 5, 6)
    fused = fusion.fuse(torch.cat([cam, lidar], 1))
    w1 = fusion.gate[1].weight.view(2, 4)
    w2 = fusion.gate[3].weight.view(4, 2)
    pooled = fused.mean(dim=(2, 3))
    gate = torch.sigmoid(torch.relu(pooled @ w1.T) @ w2.T)
    torch.testing.assert_close(fusion(cam, lidar),
                               fused * gate[:, :, None, None])
    assert sum(p.numel() for p in fusion.gate.parameters()) == 16
    assert sum(p.numel() for p in DynamicFusion2D(
        (3, 2), 4).gate.parameters()) == 20
    with pytest.raises(ValueError, match='gate must be one of'):
        DynamicFusion2D((3, 2), 4, gate='se')
