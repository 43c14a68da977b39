"""OccCylindrical's paper config exports, DCN included, and matches PyTorch
on the real nuScenes key frame.

``tools/deployment/export_onnx.py`` on
``configs/occ_cyl/occcyl_r50-swins_3xb1-24e_surroundocc-nus.py`` with
fresh weights (no checkpoint is published): the camera graph holds the
ResNet-50's nine DCNv2 layers (stages 3 and 4: 6 + 3 bottlenecks) as ONNX
``DeformConv`` (opset 19), the plane graph the Swin-S encoder and head
(opset 18); traced with synthetic sample 0 and verified on the real key
frame (1600 x 900 images, ~24 k points after the ego box), which the
graph was not traced with. Minutes on a CPU: slow tier.
"""
import os.path as osp

import pytest

from projects.occ_common.analysis.real_sample import (MISSING_REASON,
                                                      real_info_file)
from projects.occ_common.testing.tool_logs import (REPO_ROOT,
                                                   export_onnx_report,
                                                   occcyl_graph_parity)

CONFIG = osp.join(REPO_ROOT, 'configs', 'occ_cyl',
                  'occcyl_r50-swins_3xb1-24e_surroundocc-nus.py')
REAL = real_info_file()

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(REAL is None, reason=MISSING_REASON)
]


@pytest.fixture(scope='module')
def report(tmp_path_factory):
    return export_onnx_report(
        CONFIG, str(tmp_path_factory.mktemp('onnx') / 'occcyl.onnx'), [REAL])


def test_camera_graph_holds_the_dcn_layers(report):
    """Nine DeformConv nodes at opset 19 in the camera graph; the plane
    graph stays at opset 18."""
    camera, plane = report['graphs']['camera'], report['graphs']['prediction']
    assert camera['ops'].get('DeformConv') == 9 and camera['opset'] == 19
    assert 'DeformConv' not in plane['ops'] and plane['opset'] == 18


def test_parity_on_the_real_sample(report):
    """Prediction logits within 1e-3 of the model's own forward, argmax
    equal on at least 99.9 % of the voxels; depth and context within
    1e-3."""
    result, camera = occcyl_graph_parity(report, REAL)
    assert result['num_points'] > 20000
    assert max(result['max_abs_diff'], camera['max_abs_diff']) <= 1e-3
    assert result['argmax_agreement'] >= 0.999
