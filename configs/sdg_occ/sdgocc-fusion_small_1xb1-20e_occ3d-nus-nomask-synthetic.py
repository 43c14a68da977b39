# The small SDG-Fusion on the synthetic world's Occ3D labels, trained
# without the camera mask and scored with RayIoU (SparseOcc, Liu et al.,
# ECCV 2024) beside the camera-mask mIoU: the learning benchmark's
# no-mask row. The paper configs' *-nomask.py say why.
_base_ = ['./sdgocc-fusion_small_1xb1-20e_occ3d-nus-synthetic.py']

# Every voxel is supervised (the base's loss_mask_key='mask_camera' off).
model = dict(loss_mask_key=None)

# RayIoU casts rays from every key frame of the sample's scene: it reads
# their poses from the split's info file. The benchmark validates the same
# held-out samples every few hundred iterations: their GT rays are cast
# once (cache_gt_rays).
_val = _base_.val_dataloader.dataset
val_evaluator = [
    _base_.val_evaluator,
    dict(type='OccRayIoUMetric', data_root=_val.data_root,
         ann_file=_val.ann_file, cache_gt_rays=True)
]
test_evaluator = val_evaluator
