"""tools/analysis_tools/benchmark_occ_loss.py: the loss of a git revision,
timed alike."""
import json
import os.path as osp

import pytest
import torch
from mmdet3d.registry import MODELS

from projects.occ_common.models.losses import OccLovaszLoss
from projects.occ_common.testing.tool_logs import load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
TINY = osp.join(ROOT, 'configs', 'occ_cyl',
                'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')


def test_drawn_logits_favour_the_label_of_their_scale():
    """A 4 x 4 x 2 grid and its 2 x 2 x 1 scale, 3 classes, empty 0: with a
    margin of 100 over unit-normal noise every voxel's largest logit is its
    label at the finest scale, and at the coarser one the label of the
    block's first voxel (the drawing reads labels[::2, ::2, ::2]); with
    empty probability 1 every label is 0."""
    tool = load_tool('tools/analysis_tools/benchmark_occ_loss.py')
    logits, labels = tool.draw_inputs([(4, 4, 2), (2, 2, 1)], 3, 2, 0.5,
                                      100.0, 0)
    assert labels.shape == (2, 4, 4, 2)
    assert [tuple(x.shape) for x in logits] == [(2, 3, 4, 4, 2),
                                                (2, 3, 2, 2, 1)]
    assert torch.equal(logits[0].argmax(1), labels)
    assert torch.equal(logits[1].argmax(1), labels[:, ::2, ::2, ::2])
    _, empty = tool.draw_inputs([(4, 4, 2)], 3, 1, 1.0, 4.0, 0)
    assert int(empty.count_nonzero()) == 0


def test_the_reference_stays_out_of_the_registry():
    """The package at HEAD is imported as classes of its own (not the ones
    the project imported), and afterwards the registry builds the
    project's classes again."""
    tool = load_tool('tools/analysis_tools/benchmark_occ_loss.py')
    classes = tool.load_reference('HEAD')
    assert {'OccLovaszLoss', 'MultiScaleOccupancyLoss'} <= set(classes)
    assert classes['OccLovaszLoss'] is not OccLovaszLoss
    assert classes['OccLovaszLoss'].__name__ == 'OccLovaszLoss'
    assert MODELS.get('OccLovaszLoss') is OccLovaszLoss
    with tool.registered(classes):
        assert MODELS.get('OccLovaszLoss') is classes['OccLovaszLoss']
    assert MODELS.get('OccLovaszLoss') is OccLovaszLoss


def test_an_unknown_revision_is_named():
    """A revision without the loss package fails with its name."""
    tool = load_tool('tools/analysis_tools/benchmark_occ_loss.py')
    with pytest.raises(ValueError, match='no-such-revision'):
        tool.load_reference('no-such-revision')


def test_the_same_code_times_alike_and_agrees_exactly(tmp_path):
    """The tiny config's head (200 x 200 x 16 = 640,000 finest voxels, 4
    scales) against its own code at HEAD, one round each: both are timed,
    and the same code on the same inputs gives the same 16 terms (4 losses
    x 4 scales) and gradients exactly (relative difference 0)."""
    out = tmp_path / 'loss.json'
    load_tool('tools/analysis_tools/benchmark_occ_loss.py').main(
        [TINY, '--ref', 'HEAD', '--rounds', '1', '--out', str(out)])
    result = json.loads(out.read_text())['result']
    assert result['voxels'] == 200 * 200 * 16
    assert len(result['terms']) == 16
    assert 'loss_lovasz_s0' in result['terms']
    for name in ('current', 'ref'):
        assert len(result[name]['rounds']['wall_s']) == 1
        assert result[name]['cpu_s'] > 0
    assert result['max_term_rel_diff'] == 0
    assert result['max_grad_rel_diff'] == 0
