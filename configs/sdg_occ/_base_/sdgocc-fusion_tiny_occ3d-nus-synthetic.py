# The tiny SDG-Fusion (./sdgocc-fusion_tiny.py) on the synthetic world's
# Occ3D labels, without a runtime: ../sdgocc-*_tiny_1xb1-6e_*-synthetic.py
# add the CPU runtime and their delta.
_base_ = ['../../_base_/datasets/nus-occ-common.py',
          '../../_base_/datasets/occ3d-task.py', './sdgocc-fusion_r50.py',
          './sdgocc-fusion_tiny.py']

model = dict(
    _base_.tiny_model, **_base_.occ_task,
    depth_bound=[*_base_.depth_bounds.occ3d[:2], _base_.tiny_depth_step],
    lidar_encoder=dict(
        _base_.tiny_model.lidar_encoder, voxel_size=_base_.voxel_size))
# The pipelines with the 2-D semantic targets, smaller images and key-frame
# points only (sweeps_num=0 keeps the key frame and turns column 4 into
# time lag 0: ~10x fewer points for the sparse convs).
img_size = _base_.tiny_img_size
_inputs = dict(MultiViewImageAug=dict(final_size=img_size),
               LoadOccPointsFromMultiSweeps=dict(sweeps_num=0))
train_pipeline, test_pipeline = [[
    dict(t, **_inputs.get(t['type'], {}))
    for t in inputs + _base_._labels + targets + _base_._crop_and_pack
] for inputs, targets in [
    (_base_.train_inputs_seg2d, _base_.train_targets_seg2d),
    (_base_.test_inputs_seg2d, _base_.test_targets_seg2d)]]
data_root = _base_._synthetic_root
_data = dict(_base_._occ_dataset, data_root=data_root)
train_dataloader = dict(
    **_base_._synthetic_loader, dataset=dict(_data, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    **_base_._synthetic_loader, dataset=dict(_data, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric
ray_iou_metric = dict(data_root=data_root)

max_epochs = 6
train_cfg = dict(max_epochs=max_epochs, val_interval=max_epochs)
optim_wrapper = _base_.tiny_optim_wrapper
param_scheduler = []  # no warm-up: a from-scratch tiny model
