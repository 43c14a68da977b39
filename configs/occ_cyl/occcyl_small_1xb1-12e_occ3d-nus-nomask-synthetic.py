# The small OccCylindrical (_base_/occcyl_small_nus-synthetic.py) on the
# synthetic world's Occ3D labels (../_base_/datasets/occ3d-task.py), trained
# without the camera mask and scored with RayIoU beside the camera-mask
# mIoU (why: ray_iou_metric in ../_base_/datasets/nus-occ-common.py): the
# learning benchmark's no-mask row.
_base_ = ['./_base_/occcyl_small_nus-synthetic.py',
          '../_base_/datasets/occ3d-task.py', '../_base_/cpu_smoke_runtime.py']

model = dict(_base_.occ_task, loss_mask_key=None)  # every voxel supervised
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
# The benchmark validates the same samples often: their GT rays are cast
# once (cache_gt_rays).
val_evaluator = test_evaluator = [
    dict(_base_.val_evaluator, **_base_._occ_metric),
    dict(_base_.ray_iou_metric, cache_gt_rays=True)]
default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
