# A tiny OccCylindrical that trains on CPU in a few minutes on the synthetic
# nuScenes-format world (SurroundOcc labels): every module of the paper's
# model (depth-aware pseudo points, LiDAR branch, TPV-Polar-Fusion, shared
# Swin-FPN, multi-scale cylindrical head, eq. 19 loss) at a fraction of its
# width and resolution. For smoke tests and the demo, not for accuracy.
_base_ = [
    '../_base_/datasets/surroundocc-nus-synthetic.py',
    '../_base_/default_runtime.py'
]

custom_imports = dict(
    imports=['projects.occ_common', 'projects.occ_cyl'],
    allow_failed_imports=False)

# ---------------------------------------------------------------------------
# Coupled values: defined once here, everything below derives from them.
# ---------------------------------------------------------------------------
pi = 3.141592653589793
# SurroundOcc's grid, as in _base_/datasets/surroundocc-nus.py (the
# synthetic world writes full-size labels, so the output grid stays).
point_cloud_range = [-50.0, -50.0, -5.0, 50.0, 50.0, 3.0]
voxel_size = [0.5, 0.5, 0.5]
occ_size = [
    round((point_cloud_range[i + 3] - point_cloud_range[i]) / voxel_size[i])
    for i in range(3)
]  # [200, 200, 16]
num_classes = 17
ignore_index = 255
empty_index = 0
num_scales = 4
scale_shapes = [[s // 2**lvl for s in occ_size] for lvl in range(num_scales)]

# 96x160 images (a tenth of the paper's side): a 6x10 feature map.
img_size = (96, 160)
pad_divisor = 32
img_stride = 16
num_cams = 6
point_dims = 5
# 5 m depth bins (10 bins at 1, 6, ..., 46 m): 6 x 10 x 6 x 10 = 3.6k
# pseudo points.
depth_step = 5.0
depth_bound = [1.0, 51.0, depth_step]
num_depth_bins = int(round((depth_bound[1] - depth_bound[0]) / depth_step))
cyl_r_max = (max(-point_cloud_range[0], point_cloud_range[3])**2 +
             max(-point_cloud_range[1], point_cloud_range[4])**2)**0.5 + 0.01
cyl_range = [
    0.0, -pi, point_cloud_range[2], cyl_r_max, pi, point_cloud_range[5]
]
# A quarter of the paper's cylinder per axis (1 m height cells), M = 4.
cyl_grid = [32, 64, 8]
num_groups = 4
# Small widths so that a CPU iteration takes about a second.
img_channels = 16
context_channels = 8
point_channels = 8
plane_channels = 16
swin_dims = [16, 32, 64, 128]

model = dict(
    type='OccCylindrical',
    data_preprocessor=dict(
        type='Det3DDataPreprocessor',
        mean=[123.675, 116.28, 103.53],
        std=[58.395, 57.12, 57.375],
        bgr_to_rgb=True,
        pad_size_divisor=pad_divisor),
    img_encoder=dict(
        type='MultiViewImageEncoder',
        backbone=dict(
            type='mmdet.ResNet',
            depth=18,
            base_channels=8,
            num_stages=4,
            out_indices=(1, 2, 3),
            norm_cfg=dict(type='BN', requires_grad=True),
            style='pytorch',
            init_cfg=None),  # no download: trained from scratch
        neck=dict(
            type='mmdet.FPN',
            in_channels=[16, 32, 64],
            out_channels=img_channels,
            num_outs=3),
        neck_channels=img_channels,
        num_levels=3,
        out_channels=img_channels,
        out_stride=img_stride),
    depth_net=dict(
        type='DepthNet',
        in_channels=img_channels,
        mid_channels=img_channels,
        context_channels=context_channels,
        num_depth_bins=num_depth_bins,
        position_channels=3 * num_depth_bins,
        with_depth_feature=True,
        camera_param_dims=22,
        num_res_blocks=1,
        aspp_dilations=(1, 2)),
    point_branch=dict(
        type='LidarPointBranch',
        in_channels=point_dims,
        img_channels=context_channels,
        geo_channels=(point_channels, ),
        out_channels=(point_channels, )),
    tpv_fusion=dict(
        type='TPVPolarFusion',
        grid_shape=cyl_grid,
        cyl_range=cyl_range,
        cam_channels=context_channels,
        lidar_channels=point_channels,
        plane_channels=plane_channels,
        num_groups=num_groups,
        fused_lift=True),
    tpv_encoder=dict(
        type='TPVPlaneEncoder',
        backbone=dict(
            type='mmdet.SwinTransformer',
            in_channels=plane_channels,
            embed_dims=swin_dims[0],
            depths=[1, 1, 1, 1],
            num_heads=[1, 1, 2, 2],
            window_size=4,
            patch_size=2,
            strides=(2, 2, 2, 2),
            out_indices=(0, 1, 2, 3),
            init_cfg=None),
        neck=dict(
            type='mmdet.FPN',
            in_channels=swin_dims,
            out_channels=plane_channels,
            num_outs=num_scales)),
    occ_head=dict(
        type='CylindricalOccHead',
        in_channels=plane_channels,
        grid_shape=cyl_grid,
        cyl_range=cyl_range,
        pc_range=point_cloud_range,
        scale_shapes=scale_shapes,
        hidden_channels=plane_channels,
        num_classes=num_classes,
        loss_occ=dict(
            type='MultiScaleOccupancyLoss',
            num_scales=num_scales,
            empty_index=empty_index,
            ignore_index=ignore_index,
            losses=[
                dict(type='OccFocalLoss', ignore_index=ignore_index),
                dict(type='OccLovaszLoss', ignore_index=ignore_index),
                dict(
                    type='SceneClassAffinityLoss',
                    mode='geo',
                    empty_index=empty_index,
                    ignore_index=ignore_index),
                dict(
                    type='SceneClassAffinityLoss',
                    mode='sem',
                    empty_index=empty_index,
                    ignore_index=ignore_index),
            ])),
    depth_bound=depth_bound,
    loss_depth=dict(
        type='DepthBCELoss',
        depth_bound=depth_bound,
        downsample=img_stride,
        loss_weight=3.0))

train_pipeline = [
    dict(t, final_size=img_size) if t['type'] == 'MultiViewImageAug' else t
    for t in _base_.train_pipeline
]
test_pipeline = [
    dict(t, final_size=img_size) if t['type'] == 'MultiViewImageAug' else t
    for t in _base_.test_pipeline
]
# Worker processes only add start-up time on a handful of samples.
train_dataloader = dict(
    batch_size=1,
    num_workers=0,
    persistent_workers=False,
    dataset=dict(pipeline=train_pipeline))
val_dataloader = dict(
    batch_size=1,
    num_workers=0,
    persistent_workers=False,
    dataset=dict(pipeline=test_pipeline))
test_dataloader = val_dataloader

max_epochs = 6
# lr 2e-3 (40x the paper's): a from-scratch tiny model on a few samples.
optim_wrapper = dict(
    type='OptimWrapper',
    optimizer=dict(type='AdamW', lr=2e-3, weight_decay=0.01),
    clip_grad=dict(max_norm=35, norm_type=2))
param_scheduler = []
train_cfg = dict(
    type='EpochBasedTrainLoop', max_epochs=max_epochs,
    val_interval=max_epochs)
val_cfg = dict(type='ValLoop')
test_cfg = dict(type='TestLoop')
default_hooks = dict(
    logger=dict(interval=1),
    checkpoint=dict(interval=max_epochs, max_keep_ckpts=1))
randomness = dict(seed=0)
