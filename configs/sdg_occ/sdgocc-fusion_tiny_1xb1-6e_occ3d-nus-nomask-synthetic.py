# The tiny SDG-Fusion on the synthetic world's Occ3D labels, trained
# without the camera mask and scored with RayIoU (SparseOcc, Liu et al.,
# ECCV 2024) beside the camera-mask mIoU; the paper configs' *-nomask.py
# say why.
_base_ = ['./sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py']

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
