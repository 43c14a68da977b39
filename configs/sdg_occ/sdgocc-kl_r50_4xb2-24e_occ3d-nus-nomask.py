# SDG-KL on Occ3D-nuScenes trained without the camera mask and scored
# with RayIoU (SparseOcc, Liu et al., ECCV 2024) beside the camera-mask
# mIoU. Voxel mIoU with the mask rewards thick surfaces, and training with
# the mask inflates it; SparseOcc's README trains without the mask for a
# fair RayIoU, which needs whole label grids (no ignore label).
_base_ = ['./sdgocc-kl_r50_4xb2-24e_occ3d-nus.py']

# Every voxel is supervised (the base's loss_mask_key='mask_camera' off).
model = dict(loss_mask_key=None)

# RayIoU casts rays from every key frame of the sample's scene: it reads
# their poses from the split's info file.
_val = _base_.val_dataloader.dataset
val_evaluator = [
    _base_.val_evaluator,
    dict(type='OccRayIoUMetric', data_root=_val.data_root,
         ann_file=_val.ann_file)
]
test_evaluator = val_evaluator
