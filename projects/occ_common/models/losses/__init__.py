"""Losses of the occupancy plugins.

Importing this package registers ``OccFocalLoss``, ``OccLovaszLoss``,
``SceneClassAffinityLoss``, ``DepthBCELoss`` and ``MultiScaleOccupancyLoss``
in mmdet3d's ``MODELS`` registry.
"""
from .depth_bce_loss import (DepthBCELoss, depth_to_bins, num_depth_bins,
                             patch_min_depth)
from .focal_loss import OccFocalLoss
from .lovasz_loss import OccLovaszLoss, lovasz_softmax_flat
from .multi_scale_occupancy_loss import MultiScaleOccupancyLoss
from .occupancy_gt_downsample import downsample_occupancy_gt
from .scene_class_affinity_loss import SceneClassAffinityLoss

__all__ = [
    'DepthBCELoss', 'MultiScaleOccupancyLoss', 'OccFocalLoss',
    'OccLovaszLoss', 'SceneClassAffinityLoss', 'depth_to_bins',
    'downsample_occupancy_gt', 'lovasz_softmax_flat', 'num_depth_bins',
    'patch_min_depth'
]
