# A tiny OccCylindrical that trains on CPU in a few minutes on synthetic
# SurroundOcc labels, for smoke tests and the demo, not for accuracy: the
# small benchmark model (_base_/occcyl_small_nus-synthetic.py) at half its
# widths and image side on coarser cells, without its benchmark-tuned
# choices (it keeps the paper config's BatchNorm image branch and Swin patch
# stride, the dataset's BEV flips, one-layer point MLPs, no cosine decay).
_base_ = ['./_base_/occcyl_small_nus-synthetic.py',
          '../_base_/datasets/surroundocc-task.py',
          '../_base_/cpu_smoke_runtime.py']

# Small widths so that a CPU iteration takes about a second.
_img_channels = _plane_channels = 16
_context_channels = _point_channels = 8
_swin_dims = [16, 32, 64, 128]
# The coupled values, from the label format (the synthetic world writes
# full-size labels, so the output grid stays), then the smaller model.
model = dict(
    _base_.occ_task,
    # 5 m depth bins (at 1, 6, ..., 46 m): 6 x 10 x 6 x 10 = 3.6k points.
    depth_bound=[1.0, 51.0, 5.0],
    # The paper's cylinder range in 15 x 5.75 x 2 times coarser cells (1.6
    # m, 5.6 degrees, 0.5 m; each side divisible by the Swin stride 16).
    cylinder=dict(shape=[32, 64, 16]),
    img_encoder=dict(
        backbone=dict(
            base_channels=8,
            norm_cfg=dict(_delete_=True, type='BN', requires_grad=True)),
        neck=dict(in_channels=[8, 16, 32, 64], out_channels=_img_channels),
        neck_channels=_img_channels, out_channels=_img_channels,
        norm_cfg=dict(_delete_=True, type='BN')),
    depth_net=dict(
        in_channels=_img_channels, mid_channels=_img_channels,
        context_channels=_context_channels,
        norm_cfg=dict(_delete_=True, type='BN')),
    point_branch=dict(
        img_channels=_context_channels, geo_channels=(_point_channels, ),
        out_channels=(_point_channels, )),
    tpv_fusion=dict(
        cam_channels=_context_channels, lidar_channels=_point_channels,
        plane_channels=_plane_channels),
    tpv_encoder=dict(
        backbone=dict(
            in_channels=_plane_channels, embed_dims=_swin_dims[0],
            num_heads=[1, 1, 2, 2], patch_size=2, strides=(2, 2, 2, 2)),
        neck=dict(in_channels=_swin_dims, out_channels=_plane_channels)),
    occ_head=dict(
        in_channels=_plane_channels, hidden_channels=_plane_channels))

img_size = (96, 160)  # a tenth of the paper's side: a 6x10 feature map
_smaller = dict(MultiViewImageAug=dict(final_size=img_size))
train_pipeline, test_pipeline = [[
    dict(t, **_smaller.get(t['type'], {}))
    for t in inputs + _base_._labels + targets + _base_._crop_and_pack
] for inputs, targets in [(_base_.train_inputs, _base_.train_targets),
                          (_base_.test_inputs, _base_.test_targets)]]
train_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric

max_epochs = 6
train_cfg = dict(max_epochs=max_epochs, val_interval=max_epochs)
# lr 2e-3 (40x the paper's), no decay: a from-scratch tiny model on a few
# samples. The small config's warm-up (50 iterations from a tenth; the paper's:
# 500 from a third): without it the first steps (gradient norms 130-245, over
# the clip of 35) overshoot; by iteration 8 every voxel is predicted empty.
optim_wrapper = dict(optimizer=dict(lr=2e-3))
param_scheduler = _base_.param_scheduler[:1]
default_hooks = dict(checkpoint=dict(interval=max_epochs))
