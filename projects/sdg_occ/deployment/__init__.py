"""ONNX export of SDG-OCC: its inference paths as modules on tensors.

:class:`SDGCameraGraph` is SDG-KL's student (and the camera rows) in one
graph; :class:`SDGFusionDenseGraph` is SDG-Fusion with the LiDAR BEV as an
input. ``tools/deployment/export_onnx.py`` exports them (docs/export.md).
"""
from .camera_graph import SDGCameraGraph
from .fusion_graph import SDGFusionDenseGraph
from .graph_spec import sdg_graph_spec

__all__ = ['SDGCameraGraph', 'SDGFusionDenseGraph', 'sdg_graph_spec']
