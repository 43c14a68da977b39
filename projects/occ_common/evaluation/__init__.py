"""Evaluation (metrics) of the occupancy plugins.

Importing this package registers ``OccupancyMetric`` in mmdet3d's
``METRICS`` registry.
"""
from .depth_bin_accuracy import DepthBinAccuracy
from .occupancy_confusion import (confusion_matrix, geometric_iou,
                                  largest_confusions, mean_iou, per_class_iou,
                                  read_confusion_csv, write_confusion_csv)
from .occupancy_metric import (OCC3D_CLASSES, SURROUNDOCC_CLASSES,
                               OccupancyMetric)

__all__ = [
    'DepthBinAccuracy', 'OCC3D_CLASSES', 'OccupancyMetric',
    'SURROUNDOCC_CLASSES', 'confusion_matrix', 'geometric_iou',
    'largest_confusions', 'mean_iou', 'per_class_iou', 'read_confusion_csv',
    'write_confusion_csv'
]
