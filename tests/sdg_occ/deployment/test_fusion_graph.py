"""SDG-Fusion's dense part as one ONNX graph beside PyTorch's SPVCNN
(issue 50).

tools/deployment/export_onnx.py traces the tiny SDG-Fusion with synthetic
sample 0 (1,000 points) and verifies it on synthetic sample 2 (another
rig, 2,500 points) and, where ``../shared`` is present, on the real
nuScenes key frame: the graph takes the LiDAR encoder's BEV as an input
and holds the camera branch, the neighbourhood-attention fusion, the BEV
encoder and the head.
"""
import os.path as osp

import pytest

from projects.occ_common.analysis.real_sample import (MISSING_REASON,
                                                      real_info_file)
from projects.occ_common.testing.tool_logs import REPO_ROOT, export_onnx_report
from projects.sdg_occ.deployment.graph_spec import FUSION_OUTSIDE

CONFIG = osp.join(REPO_ROOT, 'configs', 'sdg_occ',
                  'sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py')
REAL = real_info_file()


@pytest.fixture(scope='module')
def report(tmp_path_factory):
    """The tool's report of one export, verified on synthetic sample 2
    and the real key frame when it is at hand."""
    return export_onnx_report(
        CONFIG, str(tmp_path_factory.mktemp('onnx') / 'fusion.onnx'),
        ['synthetic:2:2500'] + ([REAL] if REAL else []))


def test_graph_takes_the_lidar_bev_and_reads_every_input(report):
    """Seven inputs, the LiDAR BEV last (the tiny SPVCNN's 16 channels on
    the 200 x 200 BEV); the SPVCNN encoder is named as running outside;
    the attention is a compact graph (the unrolled loop had 22,189 nodes
    on its own)."""
    graph = report['graphs']['prediction']
    assert list(graph['inputs']) == [
        'imgs', 'points', 'cam2img', 'lidar2cam', 'img_aug_matrix',
        'lidar2img', 'lidar_bev'
    ]
    assert graph['inputs']['points']['shape'] == ['num_points', 5]
    assert graph['inputs']['lidar_bev']['shape'] == [1, 16, 200, 200]
    assert graph['outside_graph'] == FUSION_OUTSIDE
    assert graph['nodes'] < 2500
    assert list(report['graphs']) == ['prediction']


def test_parity_on_another_rig_and_point_count(report):
    """Logits within 1e-3 of the model's own forward, argmax equal on
    every voxel but at most 0.1 %."""
    result = report['graphs']['prediction']['verify']['synthetic:2:2500']
    assert result['num_points'] == 2500
    assert result['max_abs_diff'] <= 1e-3
    assert result['argmax_agreement'] >= 0.999
    assert result['passed']


@pytest.mark.skipif(REAL is None, reason=MISSING_REASON)
def test_parity_on_the_real_sample(report):
    """The real key frame (~24k points, real calibration) through the
    config's test pipeline."""
    result = report['graphs']['prediction']['verify'][REAL]
    assert result['num_points'] > 20000
    assert result['max_abs_diff'] <= 1e-3
    assert result['argmax_agreement'] >= 0.999
