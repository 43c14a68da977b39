"""SelectiveFPN: mmdet's FPN without the output convolutions nobody reads."""
import pytest
import torch
from mmdet.models.necks import FPN

from projects.occ_common.models.necks import SelectiveFPN


def _inputs():
    torch.manual_seed(0)
    return (torch.randn(2, 8, 8, 12), torch.randn(2, 16, 4, 6))


def test_output_equals_mmdets_first_level_with_the_same_weights():
    """SDG's neck (two levels, the finer one read): mmdet's FPN state dict
    loads with only ``fpn_convs.1.*`` left over, and level 0 is identical;
    the unused 1/32 output conv (4 x 4 x 3 x 3 + 4 = 148 parameters here)
    is not built."""
    ours = SelectiveFPN([8, 16], 4, out_indices=(0, ))
    theirs = FPN([8, 16], 4, num_outs=2)
    result = ours.load_state_dict(theirs.state_dict(), strict=False)
    assert result.missing_keys == []
    assert sorted(result.unexpected_keys) == [
        'fpn_convs.1.conv.bias', 'fpn_convs.1.conv.weight'
    ]
    count = sum(p.numel() for p in theirs.parameters()) - sum(
        p.numel() for p in ours.parameters())
    assert count == 4 * 4 * 3 * 3 + 4
    inputs = _inputs()
    (out, ) = ours(inputs)
    assert torch.equal(out, theirs(inputs)[0])


def test_every_parameter_gets_a_gradient():
    """What DDP needs: backward from the only output reaches every
    parameter (with mmdet's FPN, fpn_convs.1 got none)."""
    neck = SelectiveFPN([8, 16], 4)
    neck(_inputs())[0].sum().backward()
    assert all(p.grad is not None for p in neck.parameters())


def test_two_of_three_levels():
    """out_indices (0, 1) of three levels: two outputs at the finer two
    sizes, two output convs."""
    neck = SelectiveFPN([4, 8, 16], 4, out_indices=(0, 1))
    inputs = (torch.randn(1, 4, 16, 16), torch.randn(1, 8, 8, 8),
              torch.randn(1, 16, 4, 4))
    outs = neck(inputs)
    assert [tuple(o.shape) for o in outs] == [(1, 4, 16, 16), (1, 4, 8, 8)]
    assert len(neck.fpn_convs) == 2


@pytest.mark.parametrize('kwargs, match', [
    (dict(out_indices=(1, )), 'increase from 0'),
    (dict(out_indices=(0, 2)), 'below the 2 input levels'),
    (dict(out_indices=(0, 0)), 'increase'),
    (dict(num_outs=2), 'sets num_outs itself'),
    (dict(add_extra_convs=True), 'sets add_extra_convs itself'),
])
def test_bad_arguments_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SelectiveFPN([8, 16], 4, **kwargs)


def test_wrong_number_of_inputs():
    with pytest.raises(ValueError, match='expects 2 input levels, got 1'):
        SelectiveFPN([8, 16], 4)(_inputs()[:1])
