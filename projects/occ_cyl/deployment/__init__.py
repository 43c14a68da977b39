"""ONNX export of OccCylindrical's dense parts (docs/export.md)."""
from .graphs import (OccCylCameraGraph, OccCylPlaneGraph, fused_planes,
                     occcyl_graph_specs)

__all__ = [
    'OccCylCameraGraph', 'OccCylPlaneGraph', 'fused_planes',
    'occcyl_graph_specs'
]
