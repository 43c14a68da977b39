"""Tests of the shared DepthNet (OccCylindrical eq. 5)."""
import pytest
import torch
from mmdet3d.registry import MODELS

from projects.occ_common.models.layers import DepthNet
from projects.occ_common.testing.autograd_memory import recorded_training_step


def _net(**kwargs):
    cfg = dict(
        type='DepthNet',
        in_channels=8,
        mid_channels=8,
        context_channels=6,
        num_depth_bins=5,
        num_res_blocks=1,
        aspp_dilations=(1, 2))
    cfg.update(kwargs)
    torch.manual_seed(0)
    return MODELS.build(cfg)


def test_outputs_shapes_softmax_and_backward():
    """depth is a distribution over the 5 bins (sums to 1 per pixel), context
    has 6 channels, and every output is differentiable."""
    net = _net(position_channels=15, camera_param_dims=22, seg_channels=3)
    x = torch.randn(4, 8, 3, 5, requires_grad=True)
    out = net(x, torch.rand(4, 15, 3, 5), torch.randn(4, 22))
    assert out['depth'].shape == (4, 5, 3, 5)
    assert out['depth_logits'].shape == (4, 5, 3, 5)
    assert out['context'].shape == (4, 6, 3, 5)
    assert out['seg_logits'].shape == (4, 3, 3, 5)
    torch.testing.assert_close(out['depth'].sum(1), torch.ones(4, 3, 5))
    torch.testing.assert_close(out['depth'],
                               out['depth_logits'].softmax(1))
    loss = out['depth'][:, 0].sum() + out['context'].sum() + \
        out['seg_logits'].sum()
    loss.backward()
    assert x.grad is not None and x.grad.abs().sum() > 0
    assert net.position_embed[0].conv.weight.grad.abs().sum() > 0
    assert net.depth_se.mlp[0].weight.grad.abs().sum() > 0


def test_eq5_terms_add_up():
    """V_context = V + CNN1(V_depth) + CNN2(V_coord): the context of the full
    net minus the two embeddings, recomputed from the module's own layers,
    is the plain projection V of the reduced features."""
    net = _net(position_channels=15).eval()
    x, pos = torch.randn(2, 8, 3, 4), torch.rand(2, 15, 3, 4)
    out = net(x, pos)
    feats = net.reduce_conv(x)
    v = net.context_conv(feats)
    expected = v + net.depth_embed(out['depth']) + net.position_embed(pos)
    torch.testing.assert_close(out['context'], expected)


def test_ablation_switches():
    """Table V: without the depth feature and the position embedding the
    context is exactly the projection V; the modules are not built."""
    net = _net(with_depth_feature=False).eval()
    assert not hasattr(net, 'depth_embed')
    assert not hasattr(net, 'position_embed')
    x = torch.randn(1, 8, 2, 2)
    out = net(x)
    torch.testing.assert_close(out['context'],
                               net.context_conv(net.reduce_conv(x)))
    assert 'seg_logits' not in out


def test_segmentation_by_subclass():
    """SDG-OCC may override forward_seg instead of using seg_channels."""

    class WithSeg(DepthNet):

        def forward_seg(self, feats):
            return feats[:, :2] * 2

    net = WithSeg(8, 8, 6, 5, num_res_blocks=0, aspp_dilations=()).eval()
    x = torch.randn(1, 8, 2, 3)
    out = net(x)
    torch.testing.assert_close(out['seg_logits'],
                               net.reduce_conv(x)[:, :2] * 2)


def test_empty_batch():
    """Zero images (an empty batch) give empty outputs in eval mode."""
    net = _net().eval()
    out = net(torch.zeros(0, 8, 3, 4))
    assert out['depth'].shape == (0, 5, 3, 4)
    assert out['context'].shape == (0, 6, 3, 4)


def test_bad_inputs_raise():
    """Missing / mis-shaped embeddings and bad sizes are named."""
    with pytest.raises(ValueError, match='num_depth_bins'):
        _net(num_depth_bins=0)
    net = _net(position_channels=15)
    with pytest.raises(ValueError, match='pos_embed'):
        net(torch.randn(2, 8, 3, 4))
    with pytest.raises(ValueError, match=r'\(2, 15, 3, 4\)'):
        net(torch.randn(2, 8, 3, 4), torch.randn(2, 14, 3, 4))
    net = _net(camera_param_dims=22)
    with pytest.raises(ValueError, match='cam_params'):
        net(torch.randn(2, 8, 3, 4), None, torch.randn(2, 21))
    with pytest.raises(ValueError, match='B\\*N, C, h, w'):
        net(torch.randn(8, 3, 4))


def test_bins_derived_from_depth_bound():
    """(1, 51, 10) m gives 5 bins: the classifier predicts 5 channels;
    a num_depth_bins that disagrees is refused, none at all too."""
    net = _net(num_depth_bins=None, depth_bound=(1.0, 51.0, 10.0))
    assert net.num_depth_bins == 5 and net.depth_bound == (1.0, 51.0, 10.0)
    assert net(torch.randn(1, 8, 3, 4))['depth'].shape == (1, 5, 3, 4)
    with pytest.raises(ValueError, match='gives 5 bins'):
        _net(num_depth_bins=4, depth_bound=(1.0, 51.0, 10.0))
    with pytest.raises(ValueError, match='depth_bound or num_depth_bins'):
        _net(num_depth_bins=None)


def test_recomputed_depth_branch_is_exact():
    """``with_cp=True`` (training, float64): outputs, every parameter's
    gradient and every buffer (BatchNorm statistics after the step) equal
    ``with_cp=False``; the depth branch runs twice (forward and its
    recomputation) and its maps are not kept for the backward (at least 5
    fewer 8-channel 3 x 5 maps packed)."""
    x = torch.randn(4, 8, 3, 5, dtype=torch.float64)
    params = torch.ones(4, 22, dtype=x.dtype)
    results = []
    for with_cp in (False, True):
        net = _net(with_cp=with_cp, camera_param_dims=22).double().train()
        results.append(
            recorded_training_step(
                net, net.depth_branch, lambda: [
                    out[k] for out in [net(x, cam_params=params)]
                    for k in sorted(out)
                ]))
    (plain, plain_calls, plain_packed), (cp, cp_calls, cp_packed) = results
    for a, b in zip(plain, cp):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)
    assert (plain_calls, cp_calls) == (1, 2)
    maps = (4, 8, 3, 5)
    assert cp_packed.count(maps) < plain_packed.count(maps) - 4
