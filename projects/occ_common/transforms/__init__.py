"""Data transforms of the occupancy plugins (registered in TRANSFORMS)."""
from .bev_aug import OccBEVAug
from .corruptions import OccCorruption
from .depth_maps import PointsToDepthMaps, PointsToSemanticMaps
from .ego_points import RemoveEgoPoints
from .formatting import PackOccInputs
from .frames import PointsToEgoFrame
from .image_aug import MultiViewImageAug
from .image_loading import LoadMultiViewImagesOcc
from .loading import LoadLidarSegLabels, LoadOccupancyGT
from .photometric import MultiViewPhotoMetric
from .points_loading import LoadOccPointsFromFile, LoadOccPointsFromMultiSweeps
from .previous_frames import LoadPreviousKeyFrames

__all__ = [
    'LoadOccPointsFromFile', 'LoadOccPointsFromMultiSweeps',
    'LoadMultiViewImagesOcc', 'LoadOccupancyGT', 'LoadLidarSegLabels',
    'MultiViewImageAug', 'MultiViewPhotoMetric', 'PointsToDepthMaps',
    'PointsToSemanticMaps', 'OccBEVAug', 'PointsToEgoFrame',
    'PackOccInputs', 'RemoveEgoPoints', 'LoadPreviousKeyFrames',
    'OccCorruption'
]
