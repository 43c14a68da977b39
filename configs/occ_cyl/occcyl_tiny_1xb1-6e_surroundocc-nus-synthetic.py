# A tiny OccCylindrical that trains on CPU in a few minutes on the synthetic
# nuScenes-format world (SurroundOcc labels): every module of the paper's
# model (depth-aware pseudo points, LiDAR branch, TPV-Polar-Fusion, shared
# Swin-FPN, multi-scale cylindrical head, eq. 19 loss) at a fraction of its
# width and resolution. For smoke tests and the demo, not for accuracy.
_base_ = [
    '../_base_/datasets/surroundocc-nus-synthetic.py',
    '../_base_/cpu_smoke_runtime.py', './_base_/occcyl_r50-swins.py'
]

custom_imports = dict(
    imports=['projects.occ_common', 'projects.occ_cyl'],
    allow_failed_imports=False)

# Small widths so that a CPU iteration takes about a second.
_img_channels = 16
_context_channels = 8
_point_channels = 8
_plane_channels = 16
_swin_dims = [16, 32, 64, 128]

# The coupled values, from the dataset base (the synthetic world writes
# full-size labels, so the output grid stays), then the smaller model.
model = dict(
    _base_.occ_task,
    # 5 m depth bins (10 bins at 1, 6, ..., 46 m): 6 x 10 x 6 x 10 = 3.6k
    # pseudo points.
    depth_bound=[1.0, 51.0, 5.0],
    # The paper's cylinder range with 15 x 5.75 x 2 times coarser cells:
    # 32 x 64 x 16 (1.6 m, 5.6 degrees, 0.5 m; every side divisible by the
    # coarsest Swin stride 16), M = 4.
    cylinder=dict(shape=[32, 64, 16]),
    # No download: trained from scratch, so nothing frozen.
    pretrained=dict(
        img_backbone=dict(checkpoint=None),
        tpv_backbone=dict(checkpoint=None)),
    img_encoder=dict(
        backbone=dict(
            depth=18,
            base_channels=8,
            frozen_stages=-1,
            norm_eval=False,
            # ResNet-18's basic blocks take no deformable conv.
            dcn=None,
            stage_with_dcn=(False, False, False, False),
            # A tiny model needs no memory saving (nor do the modules
            # below): recomputation would only cost time.
            with_cp=False),
        neck=dict(in_channels=[8, 16, 32, 64], out_channels=_img_channels),
        neck_channels=_img_channels,
        out_channels=_img_channels,
        with_cp=False),
    depth_net=dict(
        in_channels=_img_channels,
        mid_channels=_img_channels,
        context_channels=_context_channels,
        num_res_blocks=1,
        aspp_dilations=(1, 2),
        with_cp=False),
    point_branch=dict(
        img_channels=_context_channels,
        geo_channels=(_point_channels, ),
        out_channels=(_point_channels, )),
    tpv_fusion=dict(
        cam_channels=_context_channels,
        lidar_channels=_point_channels,
        plane_channels=_plane_channels,
        num_groups=4,
        with_cp=False),
    tpv_encoder=dict(
        backbone=dict(
            in_channels=_plane_channels,
            embed_dims=_swin_dims[0],
            depths=[1, 1, 1, 1],
            num_heads=[1, 1, 2, 2],
            window_size=4,
            drop_path_rate=0.1,  # mmdet's default
            with_cp=False),
        neck=dict(in_channels=_swin_dims, out_channels=_plane_channels)),
    occ_head=dict(
        in_channels=_plane_channels,
        hidden_channels=_plane_channels,
        with_cp=False))

# 96x160 images (a tenth of the paper's side): a 6x10 feature map.
img_size = (96, 160)
_smaller = dict(MultiViewImageAug=dict(final_size=img_size))
train_pipeline = [
    dict(t, **_smaller.get(t['type'], {})) for t in _base_.train_pipeline
]
test_pipeline = [
    dict(t, **_smaller.get(t['type'], {})) for t in _base_.test_pipeline
]
train_dataloader = dict(dataset=dict(pipeline=train_pipeline))
val_dataloader = dict(dataset=dict(pipeline=test_pipeline))
test_dataloader = val_dataloader

max_epochs = 6
train_cfg = dict(max_epochs=max_epochs, val_interval=max_epochs)
# lr 2e-3 (40x the paper's), no decay: a from-scratch tiny model on a few
# samples. A 50-iteration linear warm-up from a tenth (the paper's is 500
# from a third): without it the first steps (gradient norms 130-245, above
# the clip of 35) overshoot, the loss rises for two iterations and after
# 8 the model predicts every voxel empty.
# From scratch, the image backbone learns at the full rate (the base's
# lr_mult 0.1 is for pretrained weights).
optim_wrapper = dict(
    optimizer=dict(lr=2e-3),
    paramwise_cfg=dict(
        custom_keys={'img_encoder.backbone': dict(lr_mult=1.0)}))
param_scheduler = [
    dict(type='LinearLR', start_factor=0.1, by_epoch=False, begin=0,
         end=50)
]
default_hooks = dict(checkpoint=dict(interval=max_epochs))
