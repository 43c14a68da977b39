# OccCylindrical on Occ3D-nuScenes trained without the camera mask and scored
# with RayIoU beside the camera-mask mIoU (why: ray_iou_metric in
# ../_base_/datasets/nus-occ-common.py).
_base_ = ['./occcyl_r50-swins_3xb1-24e_occ3d-nus.py']

model = dict(loss_mask_key=None)  # every voxel is supervised
val_evaluator = test_evaluator = [_base_.val_evaluator, _base_.ray_iou_metric]
