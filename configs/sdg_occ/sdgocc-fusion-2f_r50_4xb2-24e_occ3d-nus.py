# SDG-Fusion over T = 2 key frames (SDG-OCC Sec. 3.1: "a T-frame consequent
# sequence"): sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py with the previous key
# frame, whose camera BEV is warped into the current ego frame and fused
# with the current one before the LiDAR fusion. T = 2: the paper gives no
# T, and its Table 3 baseline (FlashOcc's BEVDet4D-style model) adds one
# adjacent key frame; with the sequential cache it costs about one image
# backbone per test sample.
_base_ = ['../_base_/datasets/nus-occ-common.py',
          '../_base_/datasets/occ3d-task.py', '../_base_/default_runtime.py',
          './_base_/sdgocc-fusion_r50.py']

num_frames = 2
model = dict(
    _base_.occ_task, depth_bound=_base_.depth_bounds.occ3d,
    num_frames=num_frames)
# The previous frames get the current frame's augmentation (inserted just
# before PackOccInputs); their LiDAR points guide their SDG lift with the
# current frame's filters (ego box, range).
_previous = dict(
    type='LoadPreviousKeyFrames', num_frames=num_frames, load_points=True,
    ego_box=_base_.ego_box, point_cloud_range=_base_.point_cloud_range,
    backend_args=_base_.backend_args)
_crop, _pack = _base_._crop_and_pack
train_pipeline = (
    _base_.train_inputs_seg2d + _base_._labels + _base_.train_targets_seg2d +
    [_crop, _previous, _pack])
test_pipeline = (
    _base_.test_inputs_seg2d + _base_._labels + _base_.test_targets_seg2d +
    [_crop, _previous, _pack])
_data = dict(_base_._occ_dataset, num_frames=num_frames)
train_dataloader = dict(
    batch_size=2, dataset=dict(_data, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_data, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric
# The LSS-lift rows' data (ablations/*-lss-2f_*): the LSS lift reads no
# LiDAR, so the previous key frames load none.
lss_data = [dict(dataset=dict(pipeline=[
    dict(t, load_points=False) if t['type'] == 'LoadPreviousKeyFrames' else t
    for t in pipeline])) for pipeline in (train_pipeline, test_pipeline)]
