"""Geometry shared by transforms, models and losses (torch only, no registry).

:mod:`.depth` defines the depth bins and the sparse LiDAR depth maps;
:mod:`.bev_warp` aligns a previous frame's BEV with the current frame.
"""
from .bev_warp import relative_pose, warp_bev
from .depth import (depth_bin_values, depth_to_bins, nearest_depth_map,
                    num_depth_bins, patch_min_depth, project_nearest,
                    project_points)

__all__ = [
    'depth_bin_values', 'depth_to_bins', 'nearest_depth_map',
    'num_depth_bins', 'patch_min_depth', 'project_nearest', 'project_points',
    'relative_pose', 'warp_bev'
]
