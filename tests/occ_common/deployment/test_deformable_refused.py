"""ONNX export refuses mmcv's deformable convolutions by name.

The legacy exporter fails on them with an AttributeError that names
neither the layer nor the cause (mmcv's symbolic writes a custom operator
onnxruntime cannot run); OccCylindrical's paper configs have DCNv2 in
ResNet stages 3-4 (issue 47).
"""
import pytest
import torch
from mmcv.ops import ModulatedDeformConv2dPack
from torch import nn

from projects.occ_common.deployment import export_graph


def test_dcn_layers_are_named_and_nothing_is_written(tmp_path):
    """A conv, then a DCNv2 under 'stage.dcn': the error names it and the
    way out; no file is written. The same model with a plain conv in its
    place exports."""
    model = nn.Sequential()
    model.add_module('stem', nn.Conv2d(3, 4, 3, padding=1))
    model.add_module('stage', nn.Sequential())
    model.stage.add_module('dcn', ModulatedDeformConv2dPack(4, 4, 3,
                                                            padding=1))
    path = tmp_path / 'dcn.onnx'
    with pytest.raises(ValueError, match=r"1 deformable convolutions .*"
                       r"\['stage\.dcn'\].*dcn=None"):
        export_graph(model, [torch.randn(1, 3, 8, 8)], str(path), ['x'],
                     ['y'])
    assert not path.exists()
    model.stage.dcn = nn.Conv2d(4, 4, 3, padding=1)
    export_graph(model, [torch.randn(1, 3, 8, 8)], str(path), ['x'], ['y'])
    assert path.exists()
