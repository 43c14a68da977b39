"""The config fingerprint notices what a refactoring must not change."""
import torch
from torch import nn

from projects.occ_common.testing.config_fingerprint import (differences,
                                                            model_fingerprint)


class _Net(nn.Module):

    def __init__(self, width=3):
        super().__init__()
        self.conv = nn.Conv2d(2, width, 1)  # 2 * width + width parameters
        self.bn = nn.BatchNorm2d(width)  # 2 * width + 3 buffers
        self.scale = nn.Parameter(torch.ones(1))


def test_counts_and_children():
    """width 3: conv 2*3 + 3 = 9, bn 3 + 3 = 6, own scale 1 -> 16 params;
    state dict: conv 2, bn 5 (weight, bias, running mean / var, count),
    own 1 -> 8 entries."""
    fp = model_fingerprint(_Net())
    assert fp['params'] == 16 and fp['state_dict_entries'] == 8
    assert {k: v['params'] for k, v in fp['modules'].items()} == {
        '': 1, 'bn': 6, 'conv': 9}
    assert differences(fp, model_fingerprint(_Net())) == []


def test_shape_and_frozen_changes_are_named():
    """A wider conv changes conv and bn; freezing a parameter (what
    ResNet's frozen_stages does) changes only the digest of its child."""
    base = model_fingerprint(_Net())
    wider = differences(base, model_fingerprint(_Net(width=4)))
    assert [line.split(':')[0] for line in wider] == [
        'params', 'child \'bn\'', 'child \'conv\'']
    net = _Net()
    net.conv.weight.requires_grad_(False)
    frozen = differences(base, model_fingerprint(net))
    assert len(frozen) == 1 and frozen[0].startswith("child 'conv'")
