"""SDG-OCC: semantic- and depth-guided BEV transformation with FOAD.

The models of SDG-OCC (Duan et al., CVPR 2025): SDG-Fusion and SDG-KL.

Importing this package registers ``SDGViewTransform``,
``NeighborhoodFusion``, ``FOADDistillLoss``, ``SDGBEVEncoder``,
``ChannelToHeightHead`` and ``SDGOcc`` in mmdet3d's ``MODELS`` registry.
"""
from ..occ_common.geometry.seg_targets import downsample_seg_labels
from .bev_encoder import SDGBEVEncoder
from .bev_pool import (BEVPoolIndexCache, BEVPoolIndices, bev_pool,
                       bev_pool_indices, bev_pool_mask)
from .c2h_head import (ChannelToHeightHead, channels_to_height,
                       height_labels_to_xyz, height_logits_to_xyz)
from .foad import FOADDistillLoss, foad_weights
from .neighborhood_fusion import (NeighborhoodFusion, neighborhood_attention,
                                  window_starts)
from .sdg_occ import SDGOcc
from .sdg_view_transform import (SDGViewTransform, key_frame_points,
                                 points_to_depth_maps)
from .semantic_diffusion import semantic_depth_diffusion
from .spvcnn_segmentor import SPVCNNSegmentor
from .virtual_points import (bilinear_incremental_discretization,
                             interpolate_depth_prob, virtual_point_depths,
                             virtual_point_offsets)

__all__ = [
    'BEVPoolIndexCache', 'BEVPoolIndices', 'ChannelToHeightHead',
    'FOADDistillLoss', 'NeighborhoodFusion', 'SDGBEVEncoder', 'SDGOcc',
    'SPVCNNSegmentor',
    'SDGViewTransform', 'bev_pool', 'bev_pool_indices', 'bev_pool_mask',
    'bilinear_incremental_discretization', 'channels_to_height',
    'downsample_seg_labels', 'foad_weights', 'height_labels_to_xyz',
    'height_logits_to_xyz',
    'interpolate_depth_prob', 'key_frame_points', 'neighborhood_attention',
    'points_to_depth_maps', 'semantic_depth_diffusion',
    'virtual_point_depths', 'virtual_point_offsets', 'window_starts'
]
