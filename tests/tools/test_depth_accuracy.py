"""tools/analysis_tools/depth_accuracy.py measures the distribution the lift
uses.

The tiny configs on the tiny world (one scene of two key frames), with an
untrained, seeded model. An oracle installed on the DepthNet replaces its
output by the one-hot of the LiDAR's nearest bins: if the tool compares
that tensor with the right depth maps, every pixel is right.
"""
import math
import os.path as osp

import pytest
import torch
from torch import nn

from projects.occ_common.geometry.depth import depth_to_bins
from projects.occ_common.testing.tool_logs import load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
OCCCYL = osp.join(ROOT, 'configs', 'occ_cyl',
                  'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')
SDG_2F = osp.join(ROOT, 'configs', 'sdg_occ',
                  'sdgocc-fusion-2f_tiny_1xb1-6e_occ3d-nus-synthetic.py')


def _checkpoint(config, path):
    """A seeded, untrained model of ``config`` saved as the Runner does."""
    from mmengine.config import Config
    from mmengine.registry import MODELS, init_default_scope
    cfg = Config.fromfile(config)
    init_default_scope('mmdet3d')
    torch.manual_seed(0)
    torch.save({'meta': {}, 'state_dict': MODELS.build(
        cfg.model).state_dict()}, path)
    return str(path)


def _build(config, world, tmp_path):
    tool = load_tool('tools/analysis_tools/depth_accuracy.py')
    args = tool.parse_args([
        config, _checkpoint(config, tmp_path / 'w.pth'), '--data-root',
        world
    ])
    return tool, tool.build(args)


def _oracle_hook(model, dataset, pattern):
    """Hooks whose DepthNet call k of a step returns the one-hot of the key
    frame's LiDAR bins where ``pattern[k]`` is 'oracle' and a uniform
    distribution where it is 'uniform' (calls past the pattern: uniform).
    A pre-hook on the model starts each step; returns the handles."""
    from mmengine.dataset import pseudo_collate
    gts = []
    for index in range(len(dataset)):
        data = model.data_preprocessor(pseudo_collate([dataset[index]]),
                                       False)
        imgs = data['inputs']['imgs']
        gts.append(model.gt_depth(data['data_samples'], imgs.device,
                                  tuple(imgs.shape[-2:])))
    state = dict(step=-1, call=0)

    def new_step(module, args, kwargs):
        state['step'] += 1
        state['call'] = 0

    def hook(module, inputs, output):
        call = state['call']
        state['call'] += 1
        gt = gts[state['step']]
        real = output['depth']
        num, bins, height, width = real.shape
        if call >= len(pattern) or pattern[call] == 'uniform':
            return dict(output, depth=torch.full_like(real, 1.0 / bins))
        onehot, _ = depth_to_bins(gt, gt.shape[-1] // width,
                                  model.depth_bound, nearest_bin=True)
        return dict(output, depth=onehot.reshape(num, height, width,
                                                 bins).permute(0, 3, 1, 2))

    return [
        model.register_forward_pre_hook(new_step, with_kwargs=True),
        model.depth_net.register_forward_hook(hook)
    ]


def _measure_with(tool, model, dataset, pattern):
    handles = _oracle_hook(model, dataset, pattern)
    try:
        return tool.measure(model, dataset)
    finally:
        for handle in handles:
            handle.remove()


def test_oracle_depth_is_all_right_and_uniform_is_chance(
        converted_tiny_world, tmp_path):
    """OccCylindrical tiny (bins at 1, 6, ..., 46 m: D = 10): the oracle
    gives 100 % right, probability 1, entropy 0 and a mass-weighted
    distance of at most half a bin (2.5 m); uniform gives probability 1/10
    and entropy ln 10 = 2.3026."""
    tool, (model, dataset) = _build(OCCCYL, converted_tiny_world, tmp_path)
    bins = model.depth_net.num_depth_bins
    oracle = _measure_with(tool, model, dataset, ['oracle'])
    uniform = _measure_with(tool, model, dataset, ['uniform'])
    untrained = tool.measure(model, dataset)
    step = model.depth_bound[2]
    assert oracle['samples'] == 2 and oracle['cells'] > 100
    assert oracle['top1'] == 100.0 and oracle['within_one_bin'] == 100.0
    assert oracle['prob_true'] == pytest.approx(1.0)
    assert oracle['entropy'] == pytest.approx(0.0, abs=1e-12)
    assert 0 < oracle['expected_error_m'] <= step / 2
    assert uniform['cells'] == oracle['cells']
    assert uniform['prob_true'] == pytest.approx(1.0 / bins)
    assert uniform['entropy'] == pytest.approx(math.log(bins))
    # The model's own (untrained) output is neither.
    assert 0 < untrained['entropy'] < math.log(bins)
    assert untrained['top1'] < 100.0


def test_the_key_frame_is_measured_not_the_previous_one(
        converted_tiny_world, tmp_path):
    """SDG-Fusion with two frames calls the DepthNet for the key frame,
    then for the previous one: the oracle on each step's first call is
    100 % right; on the second call only, the measure sees uniform."""
    tool, (model, dataset) = _build(SDG_2F, converted_tiny_world, tmp_path)
    # Without the test cache every step computes the previous frame (the
    # tiny world's first key frame is its own previous one: a cache hit).
    model.test_cache = False
    first = _measure_with(tool, model, dataset, ['oracle', 'uniform'])
    second = _measure_with(tool, model, dataset, ['uniform', 'oracle'])
    assert first['top1'] == 100.0
    assert second['prob_true'] == pytest.approx(
        1.0 / model.depth_net.num_depth_bins)


def test_command_line_writes_the_numbers(converted_tiny_world, tmp_path):
    """main() on a saved checkpoint: the printed numbers go to --json."""
    import json
    tool = load_tool('tools/analysis_tools/depth_accuracy.py')
    out = tmp_path / 'depth.json'
    numbers = tool.main([
        OCCCYL, _checkpoint(OCCCYL, tmp_path / 'w.pth'), '--data-root',
        converted_tiny_world, '--max-samples', '1', '--json', str(out)
    ])
    written = json.loads(out.read_text())
    assert written['samples'] == 1 and written['split'] == 'val'
    assert written['top1'] == pytest.approx(numbers['top1'])


def test_a_model_without_depth_net_is_refused():
    tool = load_tool('tools/analysis_tools/depth_accuracy.py')
    with pytest.raises(ValueError, match='has no depth_net'):
        tool.measure(nn.Linear(1, 1), [])
