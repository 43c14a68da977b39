# OccCylindrical (camera + LiDAR) as in the paper, without a dataset:
# ResNet50 (stages 0-3) + FPN image branch, BEVDepth-width DepthNet, PointOcc's
# cylinder, Swin-S TPV encoder, AdamW lr 5e-5 wd 0.01 with multistep decay.
# A config adds a label format and merges its coupled values into `model`;
# the detector hands them, its cylinder and depth bins to the modules.
custom_imports = dict(imports=['projects.occ_common', 'projects.occ_cyl'],
                      allow_failed_imports=False)

_img_stride = 16  # V is at 1/16 of the input (paper)
_point_dims = 5  # x, y, z, intensity, time lag (merged sweeps, dataset)
# Widths: the paper fixes only the total, 111.62 M (Table IV); published
# defaults give 111.9 M: FPN 256 (mmdet's), V and DepthNet 512 (BEVDepth's
# ResNet-50 DepthNet, ref. [15]), points 64 (lift-pool memory), planes 128,
# Swin-S ("swin-transformer": Swin-T cannot reach the budget, Swin-B or
# three Swin-T overshoot it).
_img_channels, _v_channels = 256, 512
_context_channels = _point_channels = 64
_plane_channels = 128
_swin_dims = [96, 192, 384, 768]  # Swin-S stage widths (as Swin-T)
_num_scales = 4  # 200x200x16, 100x100x8, 50x50x4, 25x25x2 (eq. 18)

model = dict(
    type='OccCylindrical',
    data_preprocessor=dict(
        type='Det3DDataPreprocessor', mean=[123.675, 116.28, 103.53],
        std=[58.395, 57.12, 57.375], bgr_to_rgb=True,
        pad_size_divisor=32),  # 900 -> 928 rows: the paper's 58 x 100 map
    # Depth bins "from 1 m to 50 m with interval d": (min, max, step), D =
    # (max - min) / step bins at 1, ..., 50 m, for DepthNet, the position
    # embedding (4 * D channels), the frustum and the depth loss.
    depth_bound=[1.0, 51.0, 1.0],
    # PointOcc's (ref. [18]) 480 x 360 x 32 cylinder, the box's inscribed
    # radius and its height, outside points clamped; Table VI's pseudo-point
    # counts within 5 %. 368 azimuth cells: every Swin level covers them.
    cylinder=dict(shape=[480, 368, 32], radius='inscribed', clamp=True),
    # Pretrained weights (docs/train_test.md): FCOS3D's caffe ResNet-101-DCN
    # (the paper's) does not fit; torchvision's ImageNet ResNet-50, DCN
    # offsets at zero (mmdet's mdconv). The Swin from ImageNet as PointOcc's,
    # but for the RGB 4 x 4 patch embedding (ours: 128 channels, 2 x 2).
    pretrained=dict(
        img_backbone=dict(
            module='img_encoder.backbone', style='pytorch',
            checkpoint='torchvision://resnet50',
            ignore=[r'^fc\.'],  # the ImageNet classifier
            allow_missing=[r'\.conv2\.conv_offset\.']),  # DCN offsets
        tpv_backbone=dict(
            module='tpv_encoder.backbone',
            checkpoint=('https://github.com/SwinTransformer/storage/releases/'
                        'download/v1.0.0/swin_small_patch4_window7_224.pth'),
            # RGB 4 x 4 patches, the classifier's final norm, the precomputed
            # attention masks (mmdet builds its own); per-level output norms.
            ignore=[r'^patch_embed\.projection\.', r'^norm\.',
                    r'\.attn_mask$'],
            allow_missing=[r'^norm[0-3]\.'])),
    img_encoder=dict(
        type='MultiViewImageEncoder',
        backbone=dict(
            # mmdet.ResNet, whose with_cp also recomputes the first block
            # after the frozen stage (~1.4 GiB at 6 x 928 x 1600).
            type='RecomputedResNet', depth=50, num_stages=4,
            out_indices=(0, 1, 2, 3),  # all feed the FPN (paper, Sec. IV.A)
            # Stage 1 and BN statistics and affine frozen, as OCCFusion's
            # (and mmdet's fine-tuning) ResNet.
            frozen_stages=1, norm_cfg=dict(type='BN', requires_grad=False),
            norm_eval=True, style='pytorch',
            # DCNv2 in stages 3-4: the paper cites DCN [21], OCCFusion uses
            # them there (+0.75 M); float32 (mmcv has no bfloat16 kernels).
            dcn=dict(type='Float32DCNv2', deform_groups=1,
                     fallback_on_stride=False),
            stage_with_dcn=(False, False, True, True),
            # Recompute each bottleneck in the backward (exact): a 6 x 928 x
            # 1600 iteration fits in memory.
            with_cp=True, init_cfg=None),  # weights: `pretrained` above
        neck=dict(type='mmdet.FPN', in_channels=[256, 512, 1024, 2048],
                  out_channels=_img_channels, num_outs=4),
        neck_channels=_img_channels, num_levels=4, out_channels=_v_channels,
        out_stride=_img_stride,
        with_cp=True),  # recompute the FPN in the backward, as the ResNet
    depth_net=dict(
        type='DepthNet', in_channels=_v_channels, mid_channels=_v_channels,
        context_channels=_context_channels, with_depth_feature=True,
        camera_param_dims=22,  # BEVDepth's camera-aware depth
        with_cp=True),  # recompute (exact; ~1.9 GiB kept otherwise)
    point_branch=dict(
        type='LidarPointBranch', in_channels=_point_dims,
        img_channels=_context_channels,
        # Raw attributes batch-normalised as PointOcc / Cylinder3D (the
        # paper is silent): 17.11 against 16.39 mIoU without (small config).
        input_norm=True,
        geo_channels=(_point_channels, _point_channels),
        out_channels=(_point_channels, _point_channels)),
    tpv_fusion=dict(
        type='TPVPolarFusion', cam_channels=_context_channels,
        lidar_channels=_point_channels, plane_channels=_plane_channels,
        num_groups=8,  # M of the spatial group pooling (paper, Table VII)
        # The lineage's forms: OCCFusion's squeeze-excitation fusion gate
        # (C -> C/2 -> C) and PointOcc's group MLP (Linear-ReLU-Linear).
        fusion_gate='squeeze_excite', group_mlp_norm=False,
        # Recompute the group pooling and MLPs (~1.9 GiB kept otherwise).
        fused_lift=True, with_cp=True),
    tpv_encoder=dict(
        type='TPVPlaneEncoder',
        backbone=dict(
            type='RecomputedSwinTransformer',  # mmdet's; non-reentrant with_cp
            in_channels=_plane_channels, embed_dims=_swin_dims[0],
            depths=[2, 2, 18, 2], num_heads=[3, 6, 12, 24], window_size=7,
            # Patch stride 2 (not 4): the finest level then has half the
            # plane resolution, matching the 200x200x16 output better.
            patch_size=2, strides=(2, 2, 2, 2), out_indices=(0, 1, 2, 3),
            drop_path_rate=0.3,  # Swin-S's (Swin paper, mmdet configs)
            # Recompute each block (exact: drop-path masks redrawn).
            with_cp=True, init_cfg=None),  # weights: `pretrained` above
        neck=dict(type='mmdet.FPN', in_channels=_swin_dims,
                  out_channels=_plane_channels, num_outs=_num_scales)),
    occ_head=dict(
        type='CylindricalOccHead', in_channels=_plane_channels,
        num_scales=_num_scales, hidden_channels=_plane_channels,
        with_cp=True,  # recompute the 640k-voxel MLP in the backward
        # Eq. 18 over the four scales; the labels come from the detector.
        loss_occ=dict(type='MultiScaleOccupancyLoss', losses=[
            dict(type='OccFocalLoss'), dict(type='OccLovaszLoss'),
            dict(type='SceneClassAffinityLoss', mode='geo'),
            dict(type='SceneClassAffinityLoss', mode='sem')])),
    # Eq. 19: lambda = 3. Each LiDAR depth trains its nearest bin point (the
    # paper is silent; BEVDepth's floor: 15.30 against 16.39 mIoU, small).
    loss_depth=dict(type='DepthBCELoss', downsample=_img_stride,
                    loss_weight=3.0, nearest_bin=True))

# AdamW lr 5e-5, weight decay 0.01, multistep decay (paper); milestones not
# given: mmdet3d's x0.1 at 20, 23 of 24. Backbone at 0.1 x the rate, clip 35
# and 500 warm-up iterations from 1/3: SurroundOcc's (OCCFusion: 5000, 1e-5).
max_epochs = 24
train_cfg = dict(type='EpochBasedTrainLoop', max_epochs=max_epochs,
                 val_interval=max_epochs)
val_cfg, test_cfg = dict(type='ValLoop'), dict(type='TestLoop')
optim_wrapper = dict(
    type='OptimWrapper',
    optimizer=dict(type='AdamW', lr=5e-5, weight_decay=0.01),
    paramwise_cfg=dict(
        custom_keys={'img_encoder.backbone': dict(lr_mult=0.1)}),
    clip_grad=dict(max_norm=35, norm_type=2))
param_scheduler = [
    dict(type='LinearLR', start_factor=1.0 / 3, by_epoch=False, begin=0,
         end=500),
    dict(type='MultiStepLR', by_epoch=True, begin=0, end=max_epochs,
         milestones=[20, 23], gamma=0.1)]
auto_scale_lr = dict(enable=False, base_batch_size=3)  # 3 GPUs x 1 (paper)

# Inputs applied to the dataset base's pipelines: 1600x900 images and "10
# LiDAR sweeps", as OCCFusion's code the key frame and 9 sweeps.
paper_inputs = dict(MultiViewImageAug=dict(final_size=(900, 1600)),
                    LoadOccPointsFromMultiSweeps=dict(sweeps_num=9))
# Augmentation (the paper names none): the lineage's (SurroundOcc,
# OCCFusion) colour distortion per view, no geometric change (small config:
# 20.05 mIoU with BEV flips, 25.57 without); ablations/occcyl-geoaug_* has it.
lineage_train_aug = dict(
    MultiViewImageAug=dict(resize_range=(1.0, 1.0), crop_x_range=(0.5, 0.5),
                           flip_prob=0.0, rot_range=(0.0, 0.0)),
    OccBEVAug=dict(flip_x_prob=0.0, flip_y_prob=0.0))
# Inserted after MultiViewImageAug in the training pipeline.
lineage_photometric = dict(type='MultiViewPhotoMetric')
