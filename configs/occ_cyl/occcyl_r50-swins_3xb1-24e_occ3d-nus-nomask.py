# OccCylindrical on Occ3D-nuScenes trained without the camera mask and scored
# with RayIoU (SparseOcc, Liu et al., ECCV 2024) beside the camera-mask
# mIoU. Voxel mIoU with the mask rewards thick surfaces, and training with
# the mask inflates it; SparseOcc's README trains without the mask for a
# fair RayIoU, which needs whole label grids (no ignore label).
_base_ = ['./occcyl_r50-swins_3xb1-24e_occ3d-nus.py']

# Every voxel is supervised (the base's loss_mask_key='mask_camera' off).
model = dict(loss_mask_key=None)
val_evaluator = test_evaluator = [_base_.val_evaluator, _base_.ray_iou_metric]
