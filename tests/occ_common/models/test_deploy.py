"""BatchNorm folding of the image backbones at inference."""
import pytest
import torch
from mmdet.models.backbones import ResNet
from torch import nn

from projects.occ_common.models.deploy import fuse_backbone_conv_bn


class _Model(nn.Module):
    """A ResNet-18 image backbone beside a conv + BN that is not one."""

    def __init__(self):
        super().__init__()
        self.backbone = ResNet(depth=18, out_indices=(1, 2, 3))
        self.head = nn.Sequential(nn.Conv2d(512, 4, 1), nn.BatchNorm2d(4))

    def forward(self, x):
        return [*self.backbone(x), self.head(self.backbone(x)[-1])]


def _randomised(seed: int) -> _Model:
    """Every BatchNorm with non-trivial statistics and affine parameters,
    so that folding them is not the identity."""
    torch.manual_seed(seed)
    model = _Model()
    for m in model.modules():
        if isinstance(m, nn.BatchNorm2d):
            m.running_mean.uniform_(-1, 1)
            m.running_var.uniform_(0.5, 2)
            m.weight.data.uniform_(0.5, 1.5)
            m.bias.data.uniform_(-0.5, 0.5)
    return model.eval()


@pytest.mark.parametrize('channels_last', [False, True])
def test_folding_keeps_outputs_and_counts_layers(channels_last):
    """ResNet-18: the stem's BN, 2 per basic block x 8 blocks, 3 downsample
    BNs = 20 folded; the head's BN (not a backbone) stays. Outputs of every
    level agree with the unfolded model to float rounding."""
    model = _randomised(0)
    x = torch.randn(1, 3, 64, 96)
    with torch.no_grad():
        expected = model(x)
        assert fuse_backbone_conv_bn(model, channels_last) == 20
        got = model(x)
    assert not any(
        isinstance(m, nn.BatchNorm2d) for m in model.backbone.modules())
    assert isinstance(model.head[1], nn.BatchNorm2d)
    for e, g in zip(expected, got):
        torch.testing.assert_close(g, e, rtol=1e-4, atol=1e-4)


def test_training_model_is_refused():
    """Folding a model in training mode would freeze its BatchNorms."""
    model = _Model().train()
    with pytest.raises(RuntimeError, match='model.eval'):
        fuse_backbone_conv_bn(model)
    assert isinstance(model.backbone.bn1, nn.BatchNorm2d)
