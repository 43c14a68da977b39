# The tiny SDG-Fusion over T = 2 key frames (the temporal delta of
# sdgocc-fusion-2f_r50_4xb2-24e_occ3d-nus.py): CPU smoke test of the
# previous-frame loading, the BEV warp and fusion, the cache.
_base_ = ['./_base_/sdgocc-fusion_tiny_occ3d-nus-synthetic.py',
          '../_base_/cpu_smoke_runtime.py']

default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
num_frames = 2
model = dict(num_frames=num_frames)
_previous = dict(
    type='LoadPreviousKeyFrames', num_frames=num_frames, load_points=True,
    ego_box=_base_.ego_box, point_cloud_range=_base_.point_cloud_range)
# Inserted just before PackOccInputs, as in the paper-size config.
train_pipeline = _base_.train_pipeline[:-1] + [
    _previous, _base_.train_pipeline[-1]]
test_pipeline = _base_.test_pipeline[:-1] + [
    _previous, _base_.test_pipeline[-1]]
train_dataloader = dict(
    dataset=dict(num_frames=num_frames, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(num_frames=num_frames, pipeline=test_pipeline))
