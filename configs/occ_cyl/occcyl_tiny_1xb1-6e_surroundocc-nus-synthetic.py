# A tiny OccCylindrical that trains on CPU in a few minutes on the synthetic
# nuScenes-format world (SurroundOcc labels): every module of the paper's
# model (depth-aware pseudo points, LiDAR branch, TPV-Polar-Fusion, shared
# Swin-FPN, multi-scale cylindrical head, eq. 19 loss) at a fraction of its
# width and resolution. For smoke tests and the demo, not for accuracy. It
# is the small benchmark model (_base_/occcyl_small_nus-synthetic.py) at
# half its widths and image side, on a coarser cylinder and depth bins, and
# without the small config's benchmark-tuned choices: it keeps the paper
# config's BatchNorm image branch and Swin patch stride, the dataset base's
# BEV flips, one layer per point MLP and no cosine decay.
_base_ = [
    './_base_/occcyl_small_nus-synthetic.py',
    '../_base_/datasets/surroundocc-task.py', '../_base_/cpu_smoke_runtime.py'
]

# Small widths so that a CPU iteration takes about a second.
_img_channels = 16
_context_channels = 8
_point_channels = 8
_plane_channels = 16
_swin_dims = [16, 32, 64, 128]

# The coupled values, from the label format (the synthetic world writes
# full-size labels, so the output grid stays), then the smaller model.
model = dict(
    _base_.occ_task,
    # 5 m depth bins (10 bins at 1, 6, ..., 46 m): 6 x 10 x 6 x 10 = 3.6k
    # pseudo points.
    depth_bound=[1.0, 51.0, 5.0],
    # The paper's cylinder range with 15 x 5.75 x 2 times coarser cells:
    # 32 x 64 x 16 (1.6 m, 5.6 degrees, 0.5 m; every side divisible by the
    # coarsest Swin stride 16).
    cylinder=dict(shape=[32, 64, 16]),
    img_encoder=dict(
        backbone=dict(
            base_channels=8,
            norm_cfg=dict(_delete_=True, type='BN', requires_grad=True)),
        neck=dict(in_channels=[8, 16, 32, 64], out_channels=_img_channels),
        neck_channels=_img_channels,
        out_channels=_img_channels,
        norm_cfg=dict(_delete_=True, type='BN')),
    depth_net=dict(
        in_channels=_img_channels,
        mid_channels=_img_channels,
        context_channels=_context_channels,
        norm_cfg=dict(_delete_=True, type='BN')),
    point_branch=dict(
        img_channels=_context_channels,
        geo_channels=(_point_channels, ),
        out_channels=(_point_channels, )),
    tpv_fusion=dict(
        cam_channels=_context_channels,
        lidar_channels=_point_channels,
        plane_channels=_plane_channels),
    tpv_encoder=dict(
        backbone=dict(
            in_channels=_plane_channels,
            embed_dims=_swin_dims[0],
            num_heads=[1, 1, 2, 2],
            patch_size=2,
            strides=(2, 2, 2, 2)),
        neck=dict(in_channels=_swin_dims, out_channels=_plane_channels)),
    occ_head=dict(
        in_channels=_plane_channels, hidden_channels=_plane_channels))

# 96x160 images (a tenth of the paper's side): a 6x10 feature map.
img_size = (96, 160)
_smaller = dict(MultiViewImageAug=dict(final_size=img_size))
train_pipeline = [
    dict(t, **_smaller.get(t['type'], {}))
    for t in _base_.train_inputs + _base_._labels + _base_.train_targets +
    _base_._crop_and_pack
]
test_pipeline = [
    dict(t, **_smaller.get(t['type'], {}))
    for t in _base_.test_inputs + _base_._labels + _base_.test_targets +
    _base_._crop_and_pack
]
train_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric

max_epochs = 6
train_cfg = dict(max_epochs=max_epochs, val_interval=max_epochs)
# lr 2e-3 (40x the paper's), no decay: a from-scratch tiny model on a few
# samples. The small config's 50-iteration linear warm-up from a tenth (the
# paper's is 500 from a third): without it the first steps (gradient norms
# 130-245, above the clip of 35) overshoot, the loss rises for two
# iterations and after 8 the model predicts every voxel empty.
optim_wrapper = dict(optimizer=dict(lr=2e-3))
param_scheduler = _base_.param_scheduler[:1]
default_hooks = dict(checkpoint=dict(interval=max_epochs))
