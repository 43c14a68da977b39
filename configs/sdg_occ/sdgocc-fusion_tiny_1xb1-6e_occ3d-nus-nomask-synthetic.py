# The tiny SDG-Fusion on the synthetic world's Occ3D labels, trained
# without the camera mask and scored with RayIoU (SparseOcc, Liu et al.,
# ECCV 2024) beside the camera-mask mIoU; the paper configs' *-nomask.py
# say why.
_base_ = [
    './_base_/sdgocc-fusion_tiny_occ3d-nus-synthetic.py',
    '../_base_/cpu_smoke_runtime.py'
]

default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
# Every voxel is supervised (the base's loss_mask_key='mask_camera' off).
model = dict(loss_mask_key=None)
val_evaluator = test_evaluator = [_base_.val_evaluator, _base_.ray_iou_metric]
