# A tiny SDG-Fusion that trains on CPU in a few minutes on the synthetic
# nuScenes-format world (Occ3D labels): every module of the full model, at
# a fraction of its width. For smoke tests and the demo, not for accuracy.
_base_ = [
    '../_base_/datasets/occ3d-nus-synthetic.py',
    '../_base_/cpu_smoke_runtime.py', './_base_/sdgocc-fusion_r50.py'
]

custom_imports = dict(
    imports=['projects.occ_common', 'projects.sdg_occ'],
    allow_failed_imports=False)

# Small widths so that a CPU iteration takes about a second.
_img_channels = 32
_cam_channels = 16
_lidar_channels = 16
_bev_channels = 32

# The coupled values, from the dataset base, then the smaller model.
model = dict(
    _base_.occ_task,
    # 1 m bins (the full configs use 0.5 m) halve the LSS fallback's points.
    depth_bound=[1.0, 45.0, 1.0],
    img_backbone=dict(
        depth=18,
        base_channels=8,
        norm_eval=True,
        # A tiny model needs no memory saving (nor do the modules below):
        # recomputation would only cost time.
        with_cp=False),
    pretrained=None,  # no download: trained from scratch
    img_neck=dict(in_channels=[32, 64], out_channels=_img_channels),
    depth_net=dict(
        in_channels=_img_channels,
        mid_channels=_img_channels,
        context_channels=_cam_channels,
        num_res_blocks=1,
        aspp_dilations=(),
        with_cp=False),
    lidar_encoder=dict(
        # One voxel per BEV cell (no down-sampling) keeps the sparse convs
        # cheap on CPU.
        voxel_size=_base_.voxel_size,
        base_channels=8,
        stage_channels=(_lidar_channels, _lidar_channels),
        stage_strides=(1, 1),
        out_channels=_lidar_channels,
        with_cp=False),
    fusion=dict(embed_dims=16, num_heads=2),
    bev_encoder=dict(
        in_channels=_cam_channels,
        stage_channels=[_cam_channels * 2, _cam_channels * 4],
        num_blocks=[1, 1],
        out_channels=_bev_channels),
    occ_head=dict(
        in_channels=_bev_channels,
        mid_channels=_bev_channels,
        # Departure for a short CPU budget: FlashOcc's masked cross-entropy
        # alone collapses to "ground and free" (measured with
        # tools/analysis_tools/benchmark_learning.py: IoU 62.08, the ground
        # layer exactly,
        # mIoU 6.4 after 100 and 200 iterations; 2.3 % of the camera-visible
        # voxels are occupied). Lovasz and the scene-class affinity terms
        # (OccCylindrical's eq. 18 set) optimise per-class IoU directly.
        loss_occ=dict(losses=[
            dict(type='OccFocalLoss', gamma=0.0),
            dict(type='OccLovaszLoss'),
            dict(type='SceneClassAffinityLoss', mode='geo'),
            dict(type='SceneClassAffinityLoss', mode='sem'),
        ])))

# The base pipelines with the 2-D semantic targets, with two CPU savings:
# 128x352 images (half the paper's 256x704 per side) and key-frame points
# only (sweeps_num=0 keeps the key frame and turns column 4 into time lag
# 0: ~10x fewer points for the sparse convs).
img_size = (128, 352)
_smaller = dict(
    MultiViewImageAug=dict(final_size=img_size),
    LoadOccPointsFromMultiSweeps=dict(sweeps_num=0))
train_pipeline = [
    dict(t, **_smaller.get(t['type'], {}))
    for t in _base_.train_pipeline_seg2d
]
test_pipeline = [
    dict(t, **_smaller.get(t['type'], {}))
    for t in _base_.test_pipeline_seg2d
]
train_dataloader = dict(dataset=dict(pipeline=train_pipeline))
val_dataloader = dict(dataset=dict(pipeline=test_pipeline))
test_dataloader = val_dataloader

max_epochs = 6
train_cfg = dict(max_epochs=max_epochs, val_interval=max_epochs)
# lr 2e-3 (20x the paper's), no warm-up: a from-scratch tiny model on a few
# samples.
optim_wrapper = dict(optimizer=dict(lr=2e-3))
param_scheduler = []
default_hooks = dict(checkpoint=dict(interval=max_epochs))
