# Table 3's "+FOAD" row (sdgocc-fusion-lss_*) over T = 2 key frames
# (../sdgocc-fusion-2f_*). The LSS lift reads no LiDAR: the previous frames
# load none (the LiDAR encoder reads the current frame's).
_base_ = ['../sdgocc-fusion-2f_r50_4xb2-24e_occ3d-nus.py']

model = _base_.lss_lift_model

_no_points = dict(LoadPreviousKeyFrames=dict(load_points=False))
train_pipeline = [
    dict(t, **_no_points.get(t['type'], {})) for t in _base_.train_pipeline]
test_pipeline = [
    dict(t, **_no_points.get(t['type'], {})) for t in _base_.test_pipeline]
train_dataloader = dict(dataset=dict(pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(dataset=dict(pipeline=test_pipeline))
