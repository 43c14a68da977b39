"""Evaluation (metrics) of the occupancy plugins.

Importing this package registers ``OccupancyMetric``,
``OccRayIoUMetric`` (:class:`RayIoUMetric`) and
``OccupancyCalibrationMetric`` in mmdet3d's ``METRICS`` registry.
"""
from .depth_bin_accuracy import DepthBinAccuracy
from .occupancy_calibration import (OccupancyCalibrationMetric,
                                    calibration_bins,
                                    expected_calibration_error)
from .occupancy_confusion import (confusion_matrix, geometric_iou,
                                  largest_confusions, mean_iou, per_class_iou,
                                  read_confusion_csv, write_confusion_csv)
from .occupancy_metric import (OCC3D_CLASSES, SURROUNDOCC_CLASSES,
                               OccupancyMetric)
from .ray_casting import RayHits, cast_rays, lidar_ray_directions
from .ray_iou import compute_ray_iou, count_ray_hits, ray_iou_from_counts
from .ray_iou_metric import RayIoUMetric
from .ray_origins import load_ray_origins, scene_ray_origins
from .robustness_summary import (corruption_error, resilience_rate,
                                 resistance_ability)

__all__ = [
    'DepthBinAccuracy', 'OCC3D_CLASSES', 'OccupancyCalibrationMetric',
    'OccupancyMetric', 'RayHits', 'RayIoUMetric', 'SURROUNDOCC_CLASSES',
    'calibration_bins', 'cast_rays', 'compute_ray_iou', 'confusion_matrix',
    'corruption_error', 'count_ray_hits', 'expected_calibration_error',
    'geometric_iou', 'largest_confusions', 'lidar_ray_directions',
    'load_ray_origins', 'mean_iou', 'per_class_iou', 'resilience_rate',
    'resistance_ability', 'ray_iou_from_counts', 'read_confusion_csv',
    'scene_ray_origins', 'write_confusion_csv'
]
