"""Losses of the occupancy plugins.

Importing this package registers ``OccFocalLoss``, ``OccLovaszLoss``,
``SceneClassAffinityLoss``, ``DepthBCELoss`` and ``MultiScaleOccupancyLoss``
in mmdet3d's ``MODELS`` registry.
"""
from .depth_bce_loss import DepthBCELoss
from .focal_loss import OccFocalLoss
from .lovasz_loss import OccLovaszLoss, lovasz_softmax_flat
from .multi_scale_occupancy_loss import MultiScaleOccupancyLoss
from .occupancy_gt_downsample import downsample_occupancy_gt
from .scene_class_affinity_loss import SceneClassAffinityLoss

__all__ = [
    'DepthBCELoss', 'MultiScaleOccupancyLoss', 'OccFocalLoss',
    'OccLovaszLoss', 'SceneClassAffinityLoss', 'downsample_occupancy_gt',
    'lovasz_softmax_flat'
]
