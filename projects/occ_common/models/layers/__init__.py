"""Layers shared by the occupancy models: DepthNet and camera geometry.

Depth bins and point projection live in :mod:`projects.occ_common.geometry`.
"""
from .camera_geometry import (POSITION_EMBED_DIMS, camera_parameter_vector,
                              create_frustum, cylindrical_position_embedding,
                              frustum_to_lidar, lidar2img_matrix)
from .cell_max import cell_max
from .cylindrical_coords import (cartesian_to_cylindrical,
                                 cylindrical_to_cartesian)
from .depth_net import DepthNet
from .float32_dcn import Float32DCNv2

__all__ = [
    'POSITION_EMBED_DIMS', 'DepthNet', 'Float32DCNv2',
    'camera_parameter_vector', 'cell_max',
    'cartesian_to_cylindrical', 'create_frustum',
    'cylindrical_position_embedding', 'cylindrical_to_cartesian',
    'frustum_to_lidar', 'lidar2img_matrix'
]
