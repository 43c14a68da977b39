# SDG-OCC Table 3, "+SDG" (48.51 mIoU): the camera branch with the SDG view
# transform, no LiDAR encoder, no fusion. The LiDAR points still guide the
# view transform (their depth maps), so predict needs them.
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = _base_.camera_sdg_model
