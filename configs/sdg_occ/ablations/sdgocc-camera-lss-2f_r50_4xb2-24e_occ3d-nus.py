# SDG-OCC Table 3's Baseline row over T = 2 key frames: the plain LSS lift
# of sdgocc-camera-lss_* (camera_lss_model) on the two-frame SDG-Fusion
# (../sdgocc-fusion-2f_*: the previous camera BEV warped into the current
# ego frame and fused). This is FlashOcc M2's temporal setting (ResNet-50,
# one adjacent frame; 37.84 mIoU in FlashOcc's table, Table 3's baseline)
# without its 4D stereo depth, which this repository leaves out (commit
# 77f68b7, 2026-11-28): the row is not M2 itself. Its data: lss_data.
_base_ = ['../sdgocc-fusion-2f_r50_4xb2-24e_occ3d-nus.py']

model = _base_.camera_lss_model

train_dataloader, val_dataloader = _base_.lss_data
test_dataloader = val_dataloader
