"""Losses of the occupancy plugins.

Importing this package registers ``OccFocalLoss``, ``OccLovaszLoss``,
``SceneClassAffinityLoss``, ``DepthBCELoss``, ``OccupancyLoss`` and
``MultiScaleOccupancyLoss`` in mmdet3d's ``MODELS`` registry. The per-voxel
terms derive from :class:`OccupancyLossTerm`; a head composes them with
:class:`OccupancyLoss` (one scale) or :class:`MultiScaleOccupancyLoss`.
"""
from .depth_bce_loss import DepthBCELoss
from .focal_loss import OccFocalLoss
from .lovasz_loss import OccLovaszLoss, lovasz_softmax_flat
from .occupancy_gt_downsample import downsample_occupancy_gt
from .occupancy_loss import (MultiScaleOccupancyLoss, OccupancyLoss,
                             OccupancyLossTerm, term_name)
from .scene_class_affinity_loss import SceneClassAffinityLoss

__all__ = [
    'DepthBCELoss', 'MultiScaleOccupancyLoss', 'OccFocalLoss',
    'OccLovaszLoss', 'OccupancyLoss', 'OccupancyLossTerm',
    'SceneClassAffinityLoss', 'downsample_occupancy_gt',
    'lovasz_softmax_flat', 'term_name'
]
