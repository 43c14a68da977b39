# A small SDG-Fusion for the held-out learning benchmark
# (tools/analysis_tools/benchmark_learning.py), without a runtime (the
# configs ../sdgocc-*_small_1xb1-20e_occ3d-nus-*synthetic.py add the CPU
# runtime and their delta): the tiny model (./sdgocc-fusion_tiny.py) with
# the key frame and 9 LiDAR sweeps, trained with a warm-up and a cosine
# decay, sized so that 2 CPU cores train it in about 40 minutes (20 epochs
# of the benchmark world's 64 training samples). The learning benchmark's
# hour stretches this schedule to 1760 iterations (`--iters 1760`): on
# these 1280 the mIoU depends on the seed (42.6 / 35.9), on 1760 every seed
# measured passes 40 (docs/reports/learning_benchmark.md).
#
# Widths stay the tiny ones: at twice them (1.66 M parameters, 2.1 s an
# iteration) the same 21 CPU-minutes scored 75.7 / 28.7 (IoU / mIoU on the
# held-out scenes) against 76.6 / 26.5 for the tiny widths, which then go on
# to 77.4 / 29.0 in the time the wide model needs for fewer iterations.
_base_ = [
    '../../_base_/datasets/nus-occ-common.py',
    '../../_base_/datasets/occ3d-task.py', './sdgocc-fusion_r50.py',
    './sdgocc-fusion_tiny.py'
]

model = dict(
    _base_.tiny_model,
    **_base_.occ_task,
    depth_bound=[*_base_.depth_bounds.occ3d[:2], _base_.tiny_depth_step],
    lidar_encoder=dict(
        _base_.tiny_model.lidar_encoder, voxel_size=_base_.voxel_size))

# The tiny configs' images; sweeps: 9 of the 10 the paper merges. The tiny
# config's key-frame-only cloud leaves the sparse LiDAR branch ~10x fewer
# points; the sweeps cost +0.15 s an iteration here and gave 65.4 / 19.6
# against 63.6 / 13.6 without them after 300 iterations (the learning
# benchmark's pilots).
img_size = _base_.tiny_img_size
_inputs = dict(
    MultiViewImageAug=dict(final_size=img_size),
    LoadOccPointsFromMultiSweeps=dict(sweeps_num=9))
train_pipeline = [
    dict(t, **_inputs.get(t['type'], {}))
    for t in _base_.train_inputs_seg2d + _base_._labels +
    _base_.train_targets_seg2d + _base_._crop_and_pack
]
test_pipeline = [
    dict(t, **_inputs.get(t['type'], {}))
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

max_epochs = 20
train_cfg = dict(max_epochs=max_epochs, val_interval=max_epochs)
# The tiny config's lr after a 50-iteration linear warm-up, decayed to 0 by
# a cosine over the run: +2 mIoU over a constant rate at the same budget on
# the benchmark world (the learning benchmark's pilots).
optim_wrapper = _base_.tiny_optim_wrapper
param_scheduler = [
    dict(type='LinearLR', start_factor=0.1, by_epoch=False, begin=0,
         end=50),
    dict(type='CosineAnnealingLR', by_epoch=True, begin=0,
         T_max=max_epochs, end=max_epochs, eta_min=0.0,
         convert_to_iter_based=True),
]
