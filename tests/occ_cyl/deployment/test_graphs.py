"""OccCylindrical's two ONNX graphs (issue 50).

tools/deployment/export_onnx.py exports the tiny OccCylindrical as a
camera graph (images and camera matrices -> DepthNet's depth and context)
and a plane graph (the three fused TPV planes -> occupancy), traced with
synthetic sample 0; the point branch and TPV-Polar-Fusion between them
run in PyTorch (``MIDDLE_OUTSIDE`` says why). Both are verified on
synthetic sample 2 (another rig, 2,500 points) and, where ``../shared``
is present, on the real nuScenes key frame.
"""
import os.path as osp

import pytest

from projects.occ_common.analysis.real_sample import (MISSING_REASON,
                                                      real_info_file)
from projects.occ_common.deployment import graph_summary
from projects.occ_common.testing.tool_logs import (REPO_ROOT,
                                                   export_onnx_report,
                                                   occcyl_graph_parity)
from projects.occ_cyl.deployment.graphs import MIDDLE_OUTSIDE

CONFIG = osp.join(REPO_ROOT, 'configs', 'occ_cyl',
                  'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')
REAL = real_info_file()


@pytest.fixture(scope='module')
def report(tmp_path_factory):
    """The tool's report of one export, verified on synthetic sample 2
    and the real key frame when it is at hand."""
    return export_onnx_report(
        CONFIG, str(tmp_path_factory.mktemp('onnx') / 'occcyl.onnx'),
        ['synthetic:2:2500'] + ([REAL] if REAL else []))


def test_two_graphs_and_what_runs_between_them(report):
    """``occcyl.onnx`` (planes in, the finest scale's logits out) and
    ``occcyl.camera.onnx`` (images and matrices in, depth and context
    out), each reading every input; the middle is named as PyTorch's."""
    graphs = report['graphs']
    assert list(graphs) == ['prediction', 'camera']
    plane, camera = graphs['prediction'], graphs['camera']
    assert list(plane['inputs']) == [
        'plane_r_theta', 'plane_theta_z', 'plane_r_z'
    ]
    assert list(plane['outputs']) == ['occ_logits', 'occ_labels']
    assert plane['outside_graph'].endswith(MIDDLE_OUTSIDE)
    assert list(camera['inputs']) == [
        'imgs', 'cam2img', 'lidar2cam', 'img_aug_matrix', 'lidar2img'
    ]
    assert list(camera['outputs']) == ['depth', 'context']
    assert camera['onnx'].endswith('occcyl.camera.onnx')
    for graph in (plane, camera):
        assert graph_summary(graph['onnx'])['unused_inputs'] == []
        assert 'Inverse' not in graph['ops']


def test_parity_on_another_rig_and_point_count(report):
    """The prediction's logits within 1e-3 of the model's own forward and
    its argmax equal on at least 99.9 % of voxels; the camera graph's
    depth and context within 1e-3 of its module's."""
    graphs = report['graphs']
    result = graphs['prediction']['verify']['synthetic:2:2500']
    assert result['num_points'] == 2500
    assert result['max_abs_diff'] <= 1e-3
    assert result['argmax_agreement'] >= 0.999
    assert graphs['camera']['verify']['synthetic:2:2500']['passed']


@pytest.mark.skipif(REAL is None, reason=MISSING_REASON)
def test_parity_on_the_real_sample(report):
    """The real key frame (~24k points, real calibration) through the
    config's test pipeline."""
    result, camera = occcyl_graph_parity(report, REAL)
    assert result['num_points'] > 20000
    assert result['max_abs_diff'] <= 1e-3
    assert result['argmax_agreement'] >= 0.999
    assert camera['max_abs_diff'] <= 1e-3
