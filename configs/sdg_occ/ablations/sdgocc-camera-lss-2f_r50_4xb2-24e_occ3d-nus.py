# SDG-OCC Table 3's Baseline row over T = 2 key frames: the plain LSS lift
# of sdgocc-camera-lss_* (camera_lss_model) on the two-frame SDG-Fusion
# (../sdgocc-fusion-2f_*: the previous camera BEV warped into the current
# ego frame and fused). This is FlashOcc M2's temporal setting (ResNet-50,
# one adjacent frame; 37.84 mIoU in FlashOcc's table, Table 3's baseline)
# without its 4D stereo depth, which this repository leaves out (commit
# 77f68b7, 2026-11-28): the row is not M2 itself. The LSS lift reads no
# LiDAR, so the previous key frames load none.
_base_ = ['../sdgocc-fusion-2f_r50_4xb2-24e_occ3d-nus.py']

model = _base_.camera_lss_model

_no_points = dict(LoadPreviousKeyFrames=dict(load_points=False))
train_pipeline = [
    dict(t, **_no_points.get(t['type'], {})) for t in _base_.train_pipeline]
test_pipeline = [
    dict(t, **_no_points.get(t['type'], {})) for t in _base_.test_pipeline]
train_dataloader = dict(dataset=dict(pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(dataset=dict(pipeline=test_pipeline))
