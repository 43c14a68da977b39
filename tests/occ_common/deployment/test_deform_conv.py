"""mmcv's modulated deformable convolutions export as ONNX ``DeformConv``.

OccCylindrical's paper configs have DCNv2 in ResNet stages 3-4; mmcv
writes them as its own custom operator, which onnxruntime cannot run.
``export_graph`` traces them as ONNX's standard ``DeformConv`` (opset 19)
instead, with mmcv's values; onnxruntime runs it.
"""
import numpy as np
import pytest
import torch
from mmcv.ops import DeformConv2dPack, ModulatedDeformConv2dPack
from torch import nn

from projects.occ_common.deployment import (export_graph, graph_summary,
                                            onnx_session, run_graph)


def _model(offset_std=0.3):
    """A conv, then a DCNv2 (stride 2, two offset groups, with bias) whose
    offsets are far from zero (std 0.3 weights, 0.5 bias: samples between
    and beyond pixels) and a bias-free one as in mmdet's ResNet."""
    torch.manual_seed(0)
    model = nn.Sequential()
    model.add_module('stem', nn.Conv2d(3, 8, 3, padding=1))
    model.add_module('dcn', ModulatedDeformConv2dPack(
        8, 6, 3, padding=1, stride=2, deform_groups=2))
    model.add_module('dcn2', ModulatedDeformConv2dPack(6, 4, 3, padding=1,
                                                       bias=False))
    for layer in (model.dcn, model.dcn2):
        nn.init.normal_(layer.conv_offset.weight, std=offset_std)
        nn.init.normal_(layer.conv_offset.bias, std=0.5)
    return model.eval()


def test_dcn_exports_as_deform_conv_with_mmcv_values(tmp_path):
    """Traced on one input, the graph (two DeformConv nodes, opset 19)
    matches mmcv's forward within 1e-5 on another input three times
    larger (offsets moved far from the traced ones); afterwards the layers
    are mmcv's again (no forward left on the instances)."""
    model = _model()
    path = export_graph(model, [torch.randn(1, 3, 12, 14)],
                        str(tmp_path / 'dcn.onnx'), ['x'], ['y'])
    summary = graph_summary(path)
    assert summary['opset'] == 19 and summary['ops']['DeformConv'] == 2
    x = 3 * torch.randn(1, 3, 12, 14)
    with torch.no_grad():
        expected = model(x).numpy()
    out = run_graph(onnx_session(path), dict(x=x))['y']
    assert out.shape == expected.shape == (1, 4, 6, 7)
    assert np.abs(out - expected).max() < 1e-5
    assert np.abs(expected).max() > 0.1
    assert 'forward' not in vars(model.dcn)


def test_an_opset_without_deform_conv_and_dcn_v1_are_refused(tmp_path):
    """Opset 18 (no DeformConv) names the layers and the opset needed;
    mmcv's unmodulated DeformConv2d has no export; no file is written."""
    path = tmp_path / 'dcn.onnx'
    with pytest.raises(ValueError, match=r"2 deformable .*\['dcn', 'dcn2'\]"
                       r".*needs opset 19"):
        export_graph(_model(), [torch.randn(1, 3, 8, 8)], str(path), ['x'],
                     ['y'], opset=18)
    v1 = nn.Sequential(DeformConv2dPack(3, 4, 3, padding=1))
    with pytest.raises(ValueError, match='unmodulated'):
        export_graph(v1, [torch.randn(1, 3, 8, 8)], str(path), ['x'], ['y'])
    assert not path.exists()


class _StemOnly(nn.Module):
    """Holds the DCN model but calls only its stem, as OccCylindrical's
    plane graph holds the whole model, DCN backbone included."""

    def __init__(self):
        super().__init__()
        self.model = _model()

    def forward(self, x):
        return self.model.stem(x)


def test_a_graph_that_calls_no_dcn_keeps_the_default_opset(tmp_path):
    """A module holding DCN layers its forward does not call: the graph
    has no DeformConv and is written at opset 18 (19 only where needed),
    matching PyTorch; an explicit opset 19 is kept."""
    module = _StemOnly().eval()
    x = torch.randn(1, 3, 8, 8)
    path = export_graph(module, [x], str(tmp_path / 'stem.onnx'), ['x'],
                        ['y'])
    summary = graph_summary(path)
    assert summary['opset'] == 18 and 'DeformConv' not in summary['ops']
    with torch.no_grad():
        expected = module(x).numpy()
    out = run_graph(onnx_session(path), dict(x=x))['y']
    assert np.abs(out - expected).max() < 1e-5
    path = export_graph(module, [x], str(tmp_path / 'stem19.onnx'), ['x'],
                        ['y'], opset=19)
    assert graph_summary(path)['opset'] == 19
