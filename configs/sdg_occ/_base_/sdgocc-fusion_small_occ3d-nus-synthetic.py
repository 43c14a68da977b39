# The small SDG-Fusion of the held-out learning benchmark, without a
# runtime (../sdgocc-*_small_* add the CPU one): the tiny model
# (./sdgocc-fusion_tiny.py) on synthetic Occ3D labels with 9 sweeps, a
# warm-up and a cosine, 20 epochs of 64 samples in ~40 minutes of 2 CPU
# cores; stretched to 1760 iterations every seed passes 40 mIoU (at 1280:
# 42.6 / 35.9; docs/reports/learning_benchmark.md). Twice the tiny widths
# scored 75.7 / 28.7 in 21 CPU-minutes against 76.6 / 26.5, and fall behind.
_base_ = ['../../_base_/datasets/nus-occ-common.py',
          '../../_base_/datasets/occ3d-task.py', './sdgocc-fusion_r50.py',
          './sdgocc-fusion_tiny.py']

model = dict(
    _base_.tiny_model, **_base_.occ_task,
    depth_bound=[*_base_.depth_bounds.occ3d[:2], _base_.tiny_depth_step],
    lidar_encoder=dict(
        _base_.tiny_model.lidar_encoder, voxel_size=_base_.voxel_size))
# The tiny configs' images; 9 of the paper's 10 sweeps (the key frame
# alone leaves the sparse branch ~10x fewer points): +0.15 s an iteration,
# 65.4 / 19.6 against 63.6 / 13.6 after 300 iterations.
img_size = _base_.tiny_img_size
_inputs = dict(MultiViewImageAug=dict(final_size=img_size),
               LoadOccPointsFromMultiSweeps=dict(sweeps_num=9))
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

max_epochs = 20
train_cfg = dict(max_epochs=max_epochs, val_interval=max_epochs)
# The tiny lr after a 50-iteration linear warm-up, decayed to 0 by a cosine
# over the run: +2 mIoU over a constant rate at the same budget.
optim_wrapper = _base_.tiny_optim_wrapper
param_scheduler = [
    dict(type='LinearLR', start_factor=0.1, by_epoch=False, begin=0, end=50),
    dict(type='CosineAnnealingLR', by_epoch=True, begin=0, T_max=max_epochs,
         end=max_epochs, eta_min=0.0, convert_to_iter_based=True)]
