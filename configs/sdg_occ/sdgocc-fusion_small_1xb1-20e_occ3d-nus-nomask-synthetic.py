# The small SDG-Fusion on the synthetic world's Occ3D labels, trained
# without the camera mask and scored with RayIoU (SparseOcc, Liu et al.,
# ECCV 2024) beside the camera-mask mIoU: the learning benchmark's no-mask
# row. The paper configs' *-nomask.py say why.
_base_ = [
    './_base_/sdgocc-fusion_small_occ3d-nus-synthetic.py',
    '../_base_/cpu_smoke_runtime.py'
]

default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
# Every voxel is supervised (the base's loss_mask_key='mask_camera' off).
model = dict(loss_mask_key=None)
# The benchmark validates the same held-out samples every few hundred
# iterations: their GT rays are cast once (cache_gt_rays).
val_evaluator = test_evaluator = [
    _base_.val_evaluator, dict(_base_.ray_iou_metric, cache_gt_rays=True)
]
