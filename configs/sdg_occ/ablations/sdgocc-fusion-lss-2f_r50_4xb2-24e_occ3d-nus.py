# Table 3's "+FOAD" row (sdgocc-fusion-lss_*) over T = 2 key frames
# (../sdgocc-fusion-2f_*); its data: lss_data (the LiDAR encoder reads the
# current frame's points).
_base_ = ['../sdgocc-fusion-2f_r50_4xb2-24e_occ3d-nus.py']

model = _base_.lss_lift_model

train_dataloader, val_dataloader = _base_.lss_data
test_dataloader = val_dataloader
