"""RecomputedResNet: mmdet's ResNet, recomputed completely and exactly."""
import pytest
import torch
from mmdet.models.backbones import ResNet

from projects.occ_common.models.backbones import RecomputedResNet
from projects.occ_common.testing.autograd_memory import (same_weights_pair,
                                                         saved_tensor_bytes)


def _pair(norm_eval, reference_with_cp):
    """A small bottleneck ResNet-50 (base 4 channels, stem and layer1
    frozen) as mmdet builds it, and the same weights in RecomputedResNet
    with ``with_cp=True``; both in training mode, float64."""
    kwargs = dict(depth=50, base_channels=4, num_stages=4,
                  out_indices=(0, 1, 2, 3), frozen_stages=1,
                  norm_eval=norm_eval)
    return same_weights_pair(ResNet, RecomputedResNet, reference_with_cp,
                             **kwargs)


def _step(model, x):
    model.zero_grad()
    outs = model(x)
    sum((out * out.flip(-1)).sum() * (i + 1)
        for i, out in enumerate(outs)).backward()
    return ([o.detach() for o in outs],
            [p.grad for p in model.parameters() if p.requires_grad],
            [b.clone() for b in model.buffers()])


@pytest.mark.parametrize('norm_eval', [True, False])
def test_same_outputs_gradients_and_statistics(norm_eval):
    """Outputs, the gradients of every trainable weight and every buffer
    (BatchNorm statistics after one training step) equal mmdet's ResNet
    without recomputation (to 1e-12 relative, float64), with frozen
    (``norm_eval``) and training BatchNorms; and the first trainable block
    (layer2, block 0, after the frozen layer1) runs twice: forward and
    recomputation."""
    reference, recomputed = _pair(norm_eval, reference_with_cp=False)
    calls = []
    recomputed.layer2[0].register_forward_pre_hook(
        lambda *a: calls.append(1))
    x = torch.randn(2, 3, 32, 48, dtype=torch.float64)
    expected, got = _step(reference, x), _step(recomputed, x)
    for a, b in zip(sum(expected, []), sum(got, [])):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)
    assert len(calls) == 2
    assert len(got[1]) == sum(
        p.numel() > 0 for n, p in recomputed.named_parameters()
        if not n.startswith(('conv1', 'bn1', 'layer1')))


def test_keeps_less_for_the_backward_than_mmdet_with_cp():
    """Bytes packed for the backward by a 1 x 3 x 64 x 96 float64 input
    (base 4 channels; the stem leaves 16 x 24): RecomputedResNet keeps
    exactly every block's input,

    - layer2: layer1's output 16 ch x 16 x 24 and three 32 ch x 8 x 12
      block outputs: (6144 + 3 * 3072) * 8 = 122,880 B;
    - layer3: one 32 ch x 8 x 12 and five 64 ch x 4 x 6: (3072 + 5 *
      1536) * 8 = 86,016 B;
    - layer4: one 64 ch x 4 x 6 and two 128 ch x 2 x 3: (1536 + 2 * 768)
      * 8 = 24,576 B;

    233,472 B in all. mmdet's ``with_cp`` skips layer2's block 0 (its
    input, layer1's output, needs no gradient), so it keeps that block's
    activations besides: more than the 8 x 16 x 24 conv1 output (24,576 B)
    on top."""
    reference, recomputed = _pair(True, reference_with_cp=True)
    x = torch.randn(1, 3, 64, 96, dtype=torch.float64)

    def packed_bytes(model):
        return saved_tensor_bytes(lambda: model(x))[1]

    assert packed_bytes(recomputed) == 233_472
    assert packed_bytes(reference) > 233_472 + 24_576
