# nuScenes + Occ3D-nuScenes occupancy labels (200x200x16, 0.4 m, ego frame;
# the task's facts: occ3d-task.py). For the synthetic world use
# occ3d-nus-synthetic.py (or override data_root). The grid and classes
# below are the coupled values of every model config on this dataset: they
# take them from occ_task.
_base_ = ['./nus-occ-common.py', './occ3d-task.py']

occ_format = _base_.occ3d.occ_format
point_cloud_range = _base_.occ3d.point_cloud_range
voxel_size = _base_.occ3d.voxel_size
grid_size = [
    round((point_cloud_range[i + 3] - point_cloud_range[i]) / voxel_size[i])
    for i in range(3)
]  # [200, 200, 16]
class_names = _base_.occ3d.class_names
num_classes = len(class_names)
empty_index = class_names.index(_base_.occ3d.empty_class)
# What every model config on this dataset merges into its `model` (the task
# arguments of the occupancy detectors): the grid, the classes, the empty
# label and, as the metric counts only camera-visible voxels, only those
# are supervised (BEVDet-Occ / FlashOcc's use_mask; neither paper says).
occ_task = dict(
    point_cloud_range=point_cloud_range,
    voxel_size=voxel_size,
    num_classes=num_classes,
    empty_index=empty_index,
    loss_mask_key='mask_camera')

_labels = _base_.occ3d.labels
_crop_and_pack = [
    dict(type='PointsRangeFilter', point_cloud_range=point_cloud_range),
    dict(type='PackOccInputs'),
]
train_pipeline = (
    _base_.train_inputs + _labels + _base_.train_targets + _crop_and_pack)
test_pipeline = (
    _base_.test_inputs + _labels + _base_.test_targets + _crop_and_pack)
# With the 2-D semantic targets (gt_seg_2d) of SDG-OCC.
train_pipeline_seg2d = (
    _base_.train_inputs_seg2d + _labels + _base_.train_targets_seg2d +
    _crop_and_pack)
test_pipeline_seg2d = (
    _base_.test_inputs_seg2d + _labels + _base_.test_targets_seg2d +
    _crop_and_pack)

_dataset = dict(occ_format=occ_format, metainfo=dict(classes=class_names))
train_dataloader = dict(dataset=dict(_dataset, pipeline=train_pipeline))
val_dataloader = dict(dataset=dict(_dataset, pipeline=test_pipeline))
test_dataloader = val_dataloader

val_evaluator = dict(
    _base_.occ3d.metric,
    class_names=class_names,
    voxel_size=voxel_size,
    point_cloud_range=point_cloud_range)
test_evaluator = val_evaluator
