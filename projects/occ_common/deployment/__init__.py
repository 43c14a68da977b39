"""ONNX export shared by the projects (``tools/deployment/export_onnx.py``).

:mod:`.onnx_export` traces a module on the GPU code path and runs the graph
with onnxruntime; :mod:`.image_preprocess` is the data preprocessor's image
steps inside a graph; :mod:`.samples` builds the samples a graph is
exported with and verified on, and their inputs; :class:`GraphSpec` is
what a project says about its exportable part.
"""
from .deform_conv import (DEFORM_CONV_OPSET, exportable_deform_convs,
                          modulated_deform_conv)
from .graph_spec import GraphSpec
from .image_preprocess import GraphImagePreprocess
from .onnx_export import (DEFAULT_OPSET, export_graph, graph_summary,
                          logits_parity, onnx_session, required_opset,
                          run_graph)
from .samples import (CAMERA_INPUTS, camera_feeds, config_time_dim,
                      info_file_sample, recalibrate, reference_logits,
                      synthetic_sample)

__all__ = [
    'CAMERA_INPUTS', 'DEFAULT_OPSET', 'DEFORM_CONV_OPSET',
    'GraphImagePreprocess', 'GraphSpec', 'camera_feeds', 'config_time_dim',
    'export_graph', 'exportable_deform_convs', 'graph_summary',
    'info_file_sample', 'logits_parity', 'modulated_deform_conv',
    'onnx_session', 'recalibrate', 'reference_logits', 'required_opset',
    'run_graph', 'synthetic_sample'
]
