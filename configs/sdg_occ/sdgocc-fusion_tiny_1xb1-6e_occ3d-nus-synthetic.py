# A tiny SDG-Fusion that trains on CPU in a few minutes on the synthetic
# nuScenes-format world (Occ3D labels): every module of the full model, at
# a fraction of its width. For smoke tests and the demo, not for accuracy.
_base_ = [
    '../_base_/datasets/occ3d-nus-synthetic.py',
    '../_base_/default_runtime.py'
]

custom_imports = dict(
    imports=['projects.occ_common', 'projects.sdg_occ'],
    allow_failed_imports=False)

# ---------------------------------------------------------------------------
# Coupled values: defined once here, everything below derives from them.
# ---------------------------------------------------------------------------
# Occ3D-nuScenes' grid, as in _base_/datasets/occ3d-nus.py (ego frame).
point_cloud_range = [-40.0, -40.0, -1.0, 40.0, 40.0, 5.4]
voxel_size = [0.4, 0.4, 0.4]
num_classes = 18
ignore_index = 255
grid_size = [
    round((point_cloud_range[i + 3] - point_cloud_range[i]) / voxel_size[i])
    for i in range(3)
]  # [200, 200, 16]
bev_shape = [grid_size[1], grid_size[0]]

img_stride = 16
# 1 m bins (the full configs use 0.5 m) halve the LSS fallback's points.
depth_bound = [1.0, 45.0, 1.0]
num_depth_bins = round((depth_bound[1] - depth_bound[0]) / depth_bound[2])
num_seg_classes = 17
# Small widths so that a CPU iteration takes about a second.
img_channels = 32
cam_channels = 16
lidar_channels = 16
bev_channels = 32
point_dims = 5

model = dict(
    type='SDGOcc',
    variant='fusion',
    data_preprocessor=dict(
        type='Det3DDataPreprocessor',
        mean=[123.675, 116.28, 103.53],
        std=[58.395, 57.12, 57.375],
        bgr_to_rgb=True,
        pad_size_divisor=32),
    downsample=img_stride,
    img_backbone=dict(
        type='mmdet.ResNet',
        depth=18,
        base_channels=8,
        num_stages=4,
        out_indices=(2, 3),
        norm_cfg=dict(type='BN', requires_grad=True),
        style='pytorch',
        init_cfg=None),  # no download: trained from scratch
    img_neck=dict(
        type='mmdet.FPN',
        in_channels=[32, 64],
        out_channels=img_channels,
        num_outs=2),
    depth_net=dict(
        type='DepthNet',
        in_channels=img_channels,
        mid_channels=img_channels,
        context_channels=cam_channels,
        num_depth_bins=num_depth_bins,
        with_depth_feature=False,
        camera_param_dims=22,
        seg_channels=num_seg_classes,
        num_res_blocks=1,
        aspp_dilations=()),
    view_transform=dict(
        type='SDGViewTransform',
        point_cloud_range=point_cloud_range,
        bev_shape=bev_shape,
        depth_bound=depth_bound,
        diffusion_radius=2.0,
        layer_radius=1.0,
        num_layers=8,
        fallback='lss'),
    lidar_encoder=dict(
        type='SPVCNNEncoder',
        in_channels=point_dims,
        # One voxel per BEV cell (no down-sampling) keeps the sparse convs
        # cheap on CPU.
        voxel_size=voxel_size,
        point_cloud_range=point_cloud_range,
        base_channels=8,
        stage_channels=(lidar_channels, lidar_channels),
        stage_strides=(1, 1),
        bev_shape=bev_shape,
        out_channels=lidar_channels),
    fusion=dict(
        type='NeighborhoodFusion',
        source_channels=lidar_channels,
        cross_channels=cam_channels,
        out_channels=cam_channels,
        embed_dims=16,
        num_heads=2,
        kernel_size=7),
    bev_encoder=dict(
        type='SDGBEVEncoder',
        in_channels=cam_channels,
        stage_channels=[cam_channels * 2, cam_channels * 4],
        num_blocks=[1, 1],
        out_channels=bev_channels),
    occ_head=dict(
        type='ChannelToHeightHead',
        in_channels=bev_channels,
        num_classes=num_classes,
        dz=grid_size[2],
        mid_channels=bev_channels,
        losses=[dict(type='OccFocalLoss', gamma=0.0,
                     ignore_index=ignore_index)],
        use_camera_mask=True,
        ignore_index=ignore_index),
    depth_loss=dict(
        type='DepthBCELoss',
        depth_bound=depth_bound,
        downsample=img_stride,
        loss_weight=0.05),
    seg_loss=dict(
        type='mmdet.CrossEntropyLoss',
        ignore_index=ignore_index,
        avg_non_ignore=True,
        loss_weight=0.5),
    seg_empty_label=0)

# The base pipelines with two CPU savings: 128x352 images (half the
# paper's 256x704 per side) and key-frame points only (no sweeps: ~10x
# fewer points for the sparse convs).
img_size = (128, 352)
occ_format = 'occ3d'
_load = [
    dict(
        type='LoadOccPointsFromFile',
        coord_type='LIDAR',
        load_dim=5,
        use_dim=5,
        backend_args=None),
    dict(type='LoadLidarSegLabels', backend_args=None),
    # sweeps_num=0 keeps the key frame and turns column 4 into time lag 0.
    dict(
        type='LoadOccPointsFromMultiSweeps',
        sweeps_num=0,
        load_dim=5,
        use_dim=[0, 1, 2, 3, 4],
        remove_close=True,
        backend_args=None),
    dict(type='LoadMultiViewImagesOcc', cam_names={{_base_.cam_names}}),
]
_finish = [
    dict(type='LoadOccupancyGT', occ_format=occ_format),
    dict(type='PointsToEgoFrame'),
]
_pack = [
    dict(type='PointsToDepthMaps'),
    dict(type='PointsToSemanticMaps'),
    dict(type='PointsRangeFilter', point_cloud_range=point_cloud_range),
    dict(type='PackOccInputs'),
]
train_pipeline = _load + [
    dict(
        type='MultiViewImageAug',
        final_size=img_size,
        resize_range=(0.94, 1.06),
        crop_x_range=(0.0, 1.0),
        crop_y_range=(1.0, 1.0),
        flip_prob=0.5,
        rot_range=(-5.4, 5.4)),
] + _finish + [dict(type='OccBEVAug', flip_x_prob=0.5, flip_y_prob=0.5)
               ] + _pack
test_pipeline = _load + [
    dict(type='MultiViewImageAug', final_size=img_size, test_mode=True),
] + _finish + [dict(type='OccBEVAug', test_mode=True)] + _pack

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
# lr 1e-3 (10x the paper's): a from-scratch tiny model on a few samples.
optim_wrapper = dict(
    type='OptimWrapper',
    optimizer=dict(type='AdamW', lr=1e-3, weight_decay=1e-2),
    clip_grad=dict(max_norm=5, norm_type=2))
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
