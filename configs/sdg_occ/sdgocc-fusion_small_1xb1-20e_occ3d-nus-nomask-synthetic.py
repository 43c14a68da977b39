# The small SDG-Fusion trained without the camera mask and scored with
# RayIoU beside the camera-mask mIoU (why: ray_iou_metric in
# ../_base_/datasets/nus-occ-common.py): the learning benchmark's no-mask
# row. It validates the same samples often: their GT rays are cast once.
_base_ = ['./_base_/sdgocc-fusion_small_occ3d-nus-synthetic.py',
          '../_base_/cpu_smoke_runtime.py']

default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
model = dict(loss_mask_key=None)  # every voxel is supervised
val_evaluator = test_evaluator = [
    _base_.val_evaluator, dict(_base_.ray_iou_metric, cache_gt_rays=True)]
