# SDG-Fusion (SDG-OCC, Duan et al., CVPR 2025) on SurroundOcc-nuScenes:
# the Occ3D config's model on SurroundOcc's 100 m grid (LiDAR frame, 0.5 m
# voxels, 17 labels with 0 = empty, no camera mask); AdamW 1e-4 with
# gradient clipping.
_base_ = [
    '../_base_/datasets/surroundocc-nus.py', '../_base_/default_runtime.py'
]

custom_imports = dict(
    imports=['projects.occ_common', 'projects.sdg_occ'],
    allow_failed_imports=False)

# ---------------------------------------------------------------------------
# Coupled values: defined once here, everything below derives from them.
# ---------------------------------------------------------------------------
# SurroundOcc's grid, as in _base_/datasets/surroundocc-nus.py (LiDAR
# frame).
point_cloud_range = [-50.0, -50.0, -5.0, 50.0, 50.0, 3.0]
voxel_size = [0.5, 0.5, 0.5]
num_classes = 17  # 0 empty, 1..16 lidarseg classes
empty_index = 0
ignore_index = 255
grid_size = [
    round((point_cloud_range[i + 3] - point_cloud_range[i]) / voxel_size[i])
    for i in range(3)
]  # [200, 200, 16]
bev_shape = [grid_size[1], grid_size[0]]  # (Y, X): one BEV cell per column

img_stride = 16  # image features at 1/16 (paper)
# Depth bins (not given by the paper): BEVDet's nuScenes 1..60 m at 0.5 m
# (118 bins), which covers the 50 m grid along every camera axis.
depth_bound = [1.0, 60.0, 0.5]
num_depth_bins = round((depth_bound[1] - depth_bound[0]) / depth_bound[2])
# Bilinear incremental discretization: r = 1 m, 8 layers (paper, Table 4).
layer_radius = 1.0
num_layers = 8
# Semantic diffusion radius in 1/16 feature pixels (not fixed by the paper):
# 2 cells = 32 image pixels, about one object width at 20 m.
diffusion_radius = 2.0
# Neighbourhood size of the fusion attention: k = 7 (paper, Table 5).
fusion_kernel = 7
# 2D semantic classes: 0 background (cells no labelled return hits), then
# the 16 lidarseg classes as projected by PointsToSemanticMaps.
num_seg_classes = 17

# Channel widths (not fixed by the paper): BEVDet-Occ / FlashOcc's 64-channel
# camera BEV, 256-channel image and head features; the SPVCNN encoder's
# default 128-channel LiDAR BEV.
img_channels = 256
cam_channels = 64
lidar_channels = 128
bev_channels = 256
point_dims = 5  # x, y, z, intensity, time lag of the merged sweeps

model = dict(
    type='SDGOcc',
    variant='fusion',
    data_preprocessor=dict(
        type='Det3DDataPreprocessor',
        # ImageNet statistics, matching the pretrained backbone.
        mean=[123.675, 116.28, 103.53],
        std=[58.395, 57.12, 57.375],
        bgr_to_rgb=True,
        pad_size_divisor=32),
    downsample=img_stride,
    img_backbone=dict(
        type='mmdet.ResNet',
        depth=50,
        num_stages=4,
        out_indices=(2, 3),
        # Whole backbone trained with live BN statistics, as BEVDet-Occ.
        frozen_stages=-1,
        norm_cfg=dict(type='BN', requires_grad=True),
        norm_eval=False,
        style='pytorch',
        # ImageNet weights, as BEVDet-Occ; set to None to train from scratch.
        init_cfg=dict(type='Pretrained', checkpoint='torchvision://resnet50')),
    img_neck=dict(
        type='mmdet.FPN',
        in_channels=[1024, 2048],
        out_channels=img_channels,
        num_outs=2),  # the 1/16 output (index 0) is used
    depth_net=dict(
        type='DepthNet',
        in_channels=img_channels,
        mid_channels=img_channels,
        context_channels=cam_channels,
        num_depth_bins=num_depth_bins,
        # SDG-OCC's context is the plain texture branch (no eq. 5 terms).
        with_depth_feature=False,
        camera_param_dims=22,  # BEVDepth's camera-aware depth, as BEVDet
        seg_channels=num_seg_classes),
    view_transform=dict(
        type='SDGViewTransform',
        point_cloud_range=point_cloud_range,
        bev_shape=bev_shape,
        depth_bound=depth_bound,
        diffusion_radius=diffusion_radius,
        layer_radius=layer_radius,
        num_layers=num_layers,
        fallback='lss',
        use_sdg=True),
    lidar_encoder=dict(
        type='SPVCNNEncoder',
        in_channels=point_dims,
        # 0.125 m voxels (SDG-OCC's 0.1 m does not divide the 0.5 m cell):
        # two stride-2 stages reach the 0.5 m BEV cell.
        voxel_size=[0.125, 0.125, 0.125],
        point_cloud_range=point_cloud_range,
        stage_strides=(2, 2),
        bev_shape=bev_shape,
        out_channels=lidar_channels),
    fusion=dict(
        type='NeighborhoodFusion',
        source_channels=lidar_channels,  # LiDAR-dominant: LiDAR queries
        cross_channels=cam_channels,
        out_channels=cam_channels,  # same width as the student camera BEV
        # Attention width (not given by the paper): the camera BEV's 64
        # channels in 4 heads of 16, NAT's head width.
        embed_dims=64,
        num_heads=4,
        kernel_size=fusion_kernel),
    bev_encoder=dict(
        type='SDGBEVEncoder',
        in_channels=cam_channels,
        # BEVDet's CustomResNet widths (2x, 4x, 8x the camera BEV).
        stage_channels=[cam_channels * 2, cam_channels * 4, cam_channels * 8],
        num_blocks=[2, 2, 2],  # BEVDet's two residual blocks per stage
        out_channels=bev_channels),
    occ_head=dict(
        type='ChannelToHeightHead',
        in_channels=bev_channels,
        num_classes=num_classes,
        dz=grid_size[2],
        mid_channels=bev_channels,
        num_convs=1,  # FlashOcc's single 3x3 conv before the predictor
        # No camera mask here, so most voxels are empty: SurroundOcc's
        # recipe of cross-entropy plus the geometric and semantic
        # scene-class affinity losses (not fixed by the SDG-OCC paper).
        losses=[
            dict(
                type='OccFocalLoss',
                gamma=0.0,
                ignore_index=ignore_index,
                loss_weight=1.0),
            dict(
                type='SceneClassAffinityLoss',
                mode='geo',
                empty_index=empty_index,
                ignore_index=ignore_index),
            dict(
                type='SceneClassAffinityLoss',
                mode='sem',
                empty_index=empty_index,
                ignore_index=ignore_index)
        ],
        use_camera_mask=False,
        ignore_index=ignore_index),
    depth_loss=dict(
        type='DepthBCELoss',
        depth_bound=depth_bound,
        downsample=img_stride,
        loss_weight=0.05),  # SDG-OCC's depth weight
    seg_loss=dict(
        type='mmdet.CrossEntropyLoss',
        ignore_index=ignore_index,
        avg_non_ignore=True,
        loss_weight=0.5),  # not fixed by the paper; BEVDet-style aux weight
    seg_empty_label=0)

# Schedule: AdamW lr 1e-4 with gradient clipping (paper). The weight decay,
# clip norm, warm-up and 24 epochs follow BEVDet-Occ / FlashOcc (not given
# in the paper); 4 GPUs x 2 samples is an assumption, hence auto_scale_lr.
max_epochs = 24
train_dataloader = dict(batch_size=2)
optim_wrapper = dict(
    type='OptimWrapper',
    optimizer=dict(type='AdamW', lr=1e-4, weight_decay=1e-2),
    clip_grad=dict(max_norm=5, norm_type=2))
param_scheduler = [
    dict(
        type='LinearLR', start_factor=1e-3, by_epoch=False, begin=0,
        end=200),
]
train_cfg = dict(
    type='EpochBasedTrainLoop', max_epochs=max_epochs,
    val_interval=max_epochs)
val_cfg = dict(type='ValLoop')
test_cfg = dict(type='TestLoop')
auto_scale_lr = dict(enable=False, base_batch_size=8)
