# OccCylindrical (camera + LiDAR) on Occ3D-nuScenes: the SurroundOcc config's
# model and schedule (occcyl_r50-swint_3xb1-24e_surroundocc-nus.py) on
# Occ3D's grid: 18 classes (17 = free), the ego frame and the camera-mask
# metric. Only the coupled values below differ; a test checks that the two
# model configs differ nowhere else.
_base_ = ['../_base_/datasets/occ3d-nus.py', '../_base_/default_runtime.py']

custom_imports = dict(
    imports=['projects.occ_common', 'projects.occ_cyl'],
    allow_failed_imports=False)

# ---------------------------------------------------------------------------
# Coupled values: defined once here, everything below derives from them.
# ---------------------------------------------------------------------------
pi = 3.141592653589793
# Occ3D-nuScenes, as in _base_/datasets/occ3d-nus.py: x, y in [-40, 40] m,
# z in [-1, 5.4] m, 0.4 m voxels, in the ego frame (PointsToEgoFrame makes
# the ego frame the working frame, so "lidar" matrices map from it).
point_cloud_range = [-40.0, -40.0, -1.0, 40.0, 40.0, 5.4]
voxel_size = [0.4, 0.4, 0.4]
occ_size = [
    round((point_cloud_range[i + 3] - point_cloud_range[i]) / voxel_size[i])
    for i in range(3)
]  # [200, 200, 16]
num_classes = 18  # 0 others, 1..16 lidarseg classes, 17 free
ignore_index = 255
empty_index = 17  # 'free'
num_scales = 4  # 200x200x16, 100x100x8, 50x50x4, 25x25x2 (eq. 18)
scale_shapes = [[s // 2**lvl for s in occ_size] for lvl in range(num_scales)]

img_size = (900, 1600)  # (H, W) network input before padding (paper)
pad_divisor = 32  # 900 -> 928 rows: the paper's 58 x 100 feature map
img_stride = 16  # V is at 1/16 of the input (paper)
num_cams = 6
point_dims = 5  # x, y, z, intensity, time lag (10 sweeps, dataset base)

# Depth bins "from 1 m to 50 m with interval d": (min, max, step) with
# D = (max - min) / step bins placed at 1, 2, ..., 50 m (d = 1 m, 50 bins).
depth_step = 1.0
depth_bound = [1.0, 51.0, depth_step]
num_depth_bins = int(round((depth_bound[1] - depth_bound[0]) / depth_step))

# The cylinder must contain every Cartesian voxel: its radius reaches the
# grid corners, (40^2 + 40^2)^0.5 = 56.57 m (+1 cm against rounding), its
# height is the grid's and its azimuth the full circle.
cyl_r_max = (max(-point_cloud_range[0], point_cloud_range[3])**2 +
             max(-point_cloud_range[1], point_cloud_range[4])**2)**0.5 + 0.01
cyl_range = [
    0.0, -pi, point_cloud_range[2], cyl_r_max, pi, point_cloud_range[5]
]
# Not fixed by the paper: R x Theta x Z = 128 x 256 x 16 as for SurroundOcc
# (0.44 m radial cells here, 1.4 degree sectors, the output's 0.4 m height).
cyl_grid = [128, 256, 16]
num_groups = 8  # M of the spatial group pooling (paper, Table VII)

# Channel widths (not fixed by the paper): 256 for the image branch as in
# BEVDepth; 64 for the pseudo / LiDAR points because the lift-pool volume
# scales with it; 128 for the TPV planes and the head.
img_channels = 256
context_channels = 64
point_channels = 64
plane_channels = 128
swin_dims = [96, 192, 384, 768]  # Swin-T stage widths

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
            depth=50,
            num_stages=4,
            out_indices=(1, 2, 3),
            frozen_stages=1,
            norm_cfg=dict(type='BN', requires_grad=True),
            norm_eval=True,
            style='pytorch',
            # FCOS3D-pretrained weights: set init_cfg=dict(type='Pretrained',
            # checkpoint='checkpoints/fcos3d.pth', prefix='backbone.').
            init_cfg=None),
        neck=dict(
            type='mmdet.FPN',
            in_channels=[512, 1024, 2048],
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
        position_channels=3 * num_depth_bins,  # (r, theta, z) per bin
        with_depth_feature=True,
        camera_param_dims=22),  # BEVDepth's camera-aware depth
    point_branch=dict(
        type='LidarPointBranch',
        in_channels=point_dims,
        img_channels=context_channels,
        geo_channels=(point_channels, point_channels),
        out_channels=(point_channels, point_channels)),
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
            depths=[2, 2, 6, 2],
            num_heads=[3, 6, 12, 24],
            window_size=7,
            # Patch stride 2 (not 4): the finest level then has half the
            # plane resolution, matching the 200x200x16 output better.
            patch_size=2,
            strides=(2, 2, 2, 2),
            out_indices=(0, 1, 2, 3),
            drop_path_rate=0.2,
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
    # Occ3D supervises only the voxels the cameras can see (the metric's
    # mask), as BEVDet-Occ and FlashOcc do; the paper does not say.
    loss_mask_key='mask_camera',
    # Eq. 19: lambda = 3.
    loss_depth=dict(
        type='DepthBCELoss',
        depth_bound=depth_bound,
        downsample=img_stride,
        loss_weight=3.0))

# The dataset base crops to BEVDet's 256x704; the paper feeds 1600x900.
train_pipeline = [
    dict(t, final_size=img_size) if t['type'] == 'MultiViewImageAug' else t
    for t in _base_.train_pipeline
]
test_pipeline = [
    dict(t, final_size=img_size) if t['type'] == 'MultiViewImageAug' else t
    for t in _base_.test_pipeline
]
train_dataloader = dict(batch_size=1, dataset=dict(pipeline=train_pipeline))
val_dataloader = dict(batch_size=1, dataset=dict(pipeline=test_pipeline))
test_dataloader = val_dataloader

# Schedule: AdamW lr 5e-5, weight decay 0.01, multistep decay (paper). The
# epoch count and milestones are not given; 24 epochs with decays at 20 and
# 23 follow SurroundOcc / OccFusion practice.
max_epochs = 24
optim_wrapper = dict(
    type='OptimWrapper',
    optimizer=dict(type='AdamW', lr=5e-5, weight_decay=0.01),
    clip_grad=dict(max_norm=35, norm_type=2))
param_scheduler = [
    dict(
        type='LinearLR', start_factor=1.0 / 3, by_epoch=False, begin=0,
        end=500),
    dict(
        type='MultiStepLR',
        by_epoch=True,
        begin=0,
        end=max_epochs,
        milestones=[20, 23],
        gamma=0.1)
]
train_cfg = dict(type='EpochBasedTrainLoop', max_epochs=max_epochs,
                 val_interval=max_epochs)
val_cfg = dict(type='ValLoop')
test_cfg = dict(type='TestLoop')
# 3 GPUs x 1 sample (paper).
auto_scale_lr = dict(enable=False, base_batch_size=3)
