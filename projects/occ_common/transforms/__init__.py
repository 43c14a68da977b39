"""Data transforms of the occupancy plugins (registered in TRANSFORMS)."""
from .bev_aug import OccBEVAug
from .depth_maps import PointsToDepthMaps, PointsToSemanticMaps
from .formatting import PackOccInputs
from .frames import PointsToEgoFrame
from .image_aug import MultiViewImageAug
from .loading import (LoadLidarSegLabels, LoadMultiViewImagesOcc,
                      LoadOccupancyGT)
from .points_loading import LoadOccPointsFromFile, LoadOccPointsFromMultiSweeps

__all__ = [
    'LoadOccPointsFromFile', 'LoadOccPointsFromMultiSweeps',
    'LoadMultiViewImagesOcc', 'LoadOccupancyGT', 'LoadLidarSegLabels',
    'MultiViewImageAug', 'PointsToDepthMaps', 'PointsToSemanticMaps',
    'OccBEVAug', 'PointsToEgoFrame', 'PackOccInputs'
]
