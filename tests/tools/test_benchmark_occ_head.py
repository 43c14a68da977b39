"""tools/analysis_tools/benchmark_occ_head.py: the head's two orders, timed
alike."""
import json
import os.path as osp

import torch

from projects.occ_common.testing.tool_logs import load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
TINY = osp.join(ROOT, 'configs', 'occ_cyl',
                'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')


def test_plane_shapes_are_what_the_encoder_outputs():
    """The tiny config's 32 x 64 x 16 cylinder through an encoder of level
    strides (2, 4, 8, 16): (R, Theta) 16 x 32, (Theta, Z) 32 x 8, (R, Z)
    16 x 8 at level 0, halved at each level; the encoder, run on zero
    planes of the cylinder's sides, outputs exactly these."""
    from mmengine.config import Config
    tool = load_tool('tools/analysis_tools/benchmark_occ_head.py')
    model = tool.build_model(Config.fromfile(TINY), hidden=None)
    shapes = tool.plane_shapes(model)
    assert shapes[0] == [(16, 32), (32, 8), (16, 8)]
    assert shapes[3] == [(2, 4), (4, 1), (2, 1)]
    sides = model.cylinder.shape
    channels = model.occ_head.classifiers[0][0].in_features
    inputs = [
        torch.zeros(1, channels, sides[a - 1], sides[b - 1])
        for _, (a, b) in tool.PLANE_POOL_AXES
    ]
    with torch.no_grad():
        out = model.tpv_encoder(inputs)
    assert [[tuple(p.shape[2:]) for p in level] for level in out] == shapes


def test_both_orders_are_timed_and_agree(tmp_path):
    """One round per order, hidden 8, on the tiny config's 200 x 200 x 16
    voxels: each order gets one wall and one CPU time, and their logits
    agree to float rounding (< 1e-5) without being identical: the two
    orders round differently, so a difference of exactly 0 would mean the
    same order ran twice."""
    out = tmp_path / 'head.json'
    load_tool('tools/analysis_tools/benchmark_occ_head.py').main(
        [TINY, '--rounds', '1', '--hidden', '8', '--out', str(out)])
    rows = json.loads(out.read_text())['rows']
    assert [r['hidden'] for r in rows] == [8]
    row = rows[0]
    assert row['voxels'] == 200 * 200 * 16
    for order in ('projected', 'summed'):
        assert len(row[order]['rounds']['wall_s']) == 1
        assert row[order]['cpu_s'] > 0
    assert 0 < row['max_abs_diff'] < 1e-5
