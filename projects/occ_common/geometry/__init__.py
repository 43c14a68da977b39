"""Geometry shared by transforms, models and losses (no registry).

:mod:`.depth` defines the depth bins and the sparse LiDAR depth maps;
:mod:`.bev_warp` aligns a previous frame's BEV with the current frame;
:mod:`.seg_targets` brings sparse 2-D semantic labels to feature resolution;
:mod:`.inverse` inverts 4x4 matrices in a form that exports to ONNX (all
torch); :mod:`.voxel_walk` walks rays through voxel grids (numpy: the
synthetic world's masks and the occupancy label generator), imported from
its module.
"""
from .bev_warp import relative_pose, warp_bev
from .depth import (DEPTH_SPACINGS, depth_bin_coordinate, depth_bin_values,
                    depth_to_bins, nearest_depth_map, normalize_depth_bound,
                    num_depth_bins, parse_depth_bound, patch_min_depth,
                    project_nearest, project_points)
from .inverse import inverse_4x4, invert_matrix
from .seg_targets import downsample_seg_labels

__all__ = [
    'DEPTH_SPACINGS', 'depth_bin_coordinate', 'depth_bin_values',
    'depth_to_bins', 'downsample_seg_labels', 'inverse_4x4', 'invert_matrix',
    'nearest_depth_map', 'normalize_depth_bound', 'num_depth_bins',
    'parse_depth_bound', 'patch_min_depth', 'project_nearest',
    'project_points', 'relative_pose', 'warp_bev'
]
