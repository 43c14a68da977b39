# The small OccCylindrical on the synthetic world's Occ3D labels, trained
# without the camera mask and scored with RayIoU (SparseOcc, Liu et al.,
# ECCV 2024) beside the camera-mask mIoU: the learning benchmark's no-mask
# row (issue 49). The model, schedule and image pipeline are the small
# SurroundOcc config's; the grid, classes, labels and metric are Occ3D's
# (../_base_/datasets/occ3d-task.py), as in the paper's Occ3D config.
_base_ = [
    './occcyl_small_1xb1-12e_surroundocc-nus-synthetic.py',
    '../_base_/datasets/occ3d-task.py'
]

_task = _base_.occ3d
occ_format = _task.occ_format
point_cloud_range = _task.point_cloud_range
voxel_size = _task.voxel_size
grid_size = [
    round((point_cloud_range[i + 3] - point_cloud_range[i]) / voxel_size[i])
    for i in range(3)
]  # [200, 200, 16]
class_names = _task.class_names
num_classes = len(class_names)
empty_index = class_names.index(_task.empty_class)
# Every voxel is supervised (no loss_mask_key), as the paper configs'
# *-nomask.py.
occ_task = dict(
    point_cloud_range=point_cloud_range,
    voxel_size=voxel_size,
    num_classes=num_classes,
    empty_index=empty_index,
    loss_mask_key=None)
model = occ_task

# SurroundOcc's label step becomes Occ3D's (labels, then the ego frame),
# and the points are cropped to Occ3D's range.
_occ3d = dict(
    LoadOccupancyGT=_task.labels,
    PointsRangeFilter=[
        dict(type='PointsRangeFilter', point_cloud_range=point_cloud_range)
    ])
train_pipeline = [
    step for t in _base_.train_pipeline
    for step in _occ3d.get(t['type'], [t])
]
test_pipeline = [
    step for t in _base_.test_pipeline
    for step in _occ3d.get(t['type'], [t])
]
_dataset = dict(occ_format=occ_format, metainfo=dict(classes=class_names))
train_dataloader = dict(dataset=dict(_dataset, pipeline=train_pipeline))
val_dataloader = dict(dataset=dict(_dataset, pipeline=test_pipeline))
test_dataloader = val_dataloader

# The camera-mask mIoU, and RayIoU from every key frame of the sample's
# scene (its poses from the split's info file; the GT rays cast once for
# the benchmark's repeated validations).
_val = _base_.val_dataloader.dataset
val_evaluator = [
    dict(
        _base_.val_evaluator,
        **_task.metric,
        class_names=class_names,
        voxel_size=voxel_size,
        point_cloud_range=point_cloud_range),
    dict(type='OccRayIoUMetric', data_root=_val.data_root,
         ann_file=_val.ann_file, cache_gt_rays=True)
]
test_evaluator = val_evaluator
