"""Evaluation (metrics) of the occupancy plugins.

Importing this package registers ``OccupancyMetric`` and
``OccRayIoUMetric`` (:class:`RayIoUMetric`) in mmdet3d's ``METRICS``
registry.
"""
from .depth_bin_accuracy import DepthBinAccuracy
from .occupancy_confusion import (confusion_matrix, geometric_iou,
                                  largest_confusions, mean_iou, per_class_iou,
                                  read_confusion_csv, write_confusion_csv)
from .occupancy_metric import (OCC3D_CLASSES, SURROUNDOCC_CLASSES,
                               OccupancyMetric)
from .ray_casting import RayHits, cast_rays, lidar_ray_directions
from .ray_iou import compute_ray_iou, count_ray_hits, ray_iou_from_counts
from .ray_iou_metric import RayIoUMetric
from .ray_origins import load_ray_origins, scene_ray_origins

__all__ = [
    'DepthBinAccuracy', 'OCC3D_CLASSES', 'OccupancyMetric', 'RayHits',
    'RayIoUMetric', 'SURROUNDOCC_CLASSES', 'cast_rays', 'compute_ray_iou',
    'confusion_matrix', 'count_ray_hits', 'geometric_iou',
    'largest_confusions', 'lidar_ray_directions', 'load_ray_origins',
    'mean_iou', 'per_class_iou', 'ray_iou_from_counts', 'read_confusion_csv',
    'scene_ray_origins', 'write_confusion_csv'
]
