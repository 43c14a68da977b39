# The small OccCylindrical on the synthetic world's Occ3D labels, trained
# without the camera mask and scored with RayIoU (SparseOcc, Liu et al.,
# ECCV 2024) beside the camera-mask mIoU: the learning benchmark's no-mask
# row. The model, schedule and image pipeline are the small config's
# (_base_/occcyl_small_nus-synthetic.py); the grid, classes, labels and
# metric are Occ3D's (../_base_/datasets/occ3d-task.py), as in the paper's
# Occ3D config.
_base_ = [
    './_base_/occcyl_small_nus-synthetic.py',
    '../_base_/datasets/occ3d-task.py', '../_base_/cpu_smoke_runtime.py'
]

# Every voxel is supervised (no loss_mask_key), as the paper configs'
# *-nomask.py.
model = dict(_base_.occ_task, loss_mask_key=None)
train_pipeline = (
    _base_._small_train_inputs + _base_._labels +
    _base_._small_train_targets + _base_._crop_and_pack)
test_pipeline = (
    _base_._small_test_inputs + _base_._labels + _base_.test_targets +
    _base_._crop_and_pack)
train_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=test_pipeline))
# The camera-mask mIoU, and RayIoU (its GT rays cast once for the
# benchmark's repeated validations).
val_evaluator = test_evaluator = [
    dict(_base_.val_evaluator, **_base_._occ_metric),
    dict(_base_.ray_iou_metric, cache_gt_rays=True)
]
default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
