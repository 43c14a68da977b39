# SDG-OCC Table 3's Baseline row in FlashOcc M1's setting: the plain LSS
# lift, no LiDAR encoder, no fusion; predict needs no LiDAR points. Single
# frame without stereo, this is FlashOcc M1 (ResNet-50, 32.08 mIoU in
# FlashOcc's table). Table 3's 37.84 is FlashOcc M2, which adds 4D stereo
# over one adjacent frame: sdgocc-camera-lss-2f_* is its two frames on
# this repository's temporal machinery, without the stereo (left out,
# commit 77f68b7). The model base's camera_lss_model says what it drops.
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = _base_.camera_lss_model
