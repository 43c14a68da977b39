# The tiny SDG-Fusion (./sdgocc-fusion_tiny.py) on the synthetic
# nuScenes-format world's Occ3D labels, without a runtime: the configs
# ../sdgocc-*_tiny_1xb1-6e_occ3d-nus-*synthetic.py add the CPU runtime
# (../../_base_/cpu_smoke_runtime.py) and their delta.
_base_ = [
    '../../_base_/datasets/nus-occ-common.py',
    '../../_base_/datasets/occ3d-task.py', './sdgocc-fusion_r50.py',
    './sdgocc-fusion_tiny.py'
]

# The coupled values, from the label format, then the smaller model.
model = dict(
    _base_.tiny_model,
    **_base_.occ_task,
    depth_bound=[*_base_.depth_bounds.occ3d[:2], _base_.tiny_depth_step],
    lidar_encoder=dict(
        _base_.tiny_model.lidar_encoder, voxel_size=_base_.voxel_size))

# The pipelines with the 2-D semantic targets, with two CPU savings:
# smaller images and key-frame points only (sweeps_num=0 keeps the key
# frame and turns column 4 into time lag 0: ~10x fewer points for the
# sparse convs).
img_size = _base_.tiny_img_size
_smaller = dict(
    MultiViewImageAug=dict(final_size=img_size),
    LoadOccPointsFromMultiSweeps=dict(sweeps_num=0))
train_pipeline = [
    dict(t, **_smaller.get(t['type'], {}))
    for t in _base_.train_inputs_seg2d + _base_._labels +
    _base_.train_targets_seg2d + _base_._crop_and_pack
]
test_pipeline = [
    dict(t, **_smaller.get(t['type'], {}))
    for t in _base_.test_inputs_seg2d + _base_._labels +
    _base_.test_targets_seg2d + _base_._crop_and_pack
]
data_root = _base_._synthetic_root
train_dataloader = dict(
    **_base_._synthetic_loader,
    dataset=dict(
        _base_._occ_dataset, data_root=data_root, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    **_base_._synthetic_loader,
    dataset=dict(
        _base_._occ_dataset, data_root=data_root, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric
ray_iou_metric = dict(data_root=data_root)

max_epochs = 6
train_cfg = dict(max_epochs=max_epochs, val_interval=max_epochs)
# No warm-up: a from-scratch tiny model on a few samples.
optim_wrapper = _base_.tiny_optim_wrapper
param_scheduler = []
