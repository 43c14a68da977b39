# A small OccCylindrical for the held-out learning benchmark
# (tools/analysis_tools/benchmark_learning.py) on the synthetic
# nuScenes-format world, without a label format or a runtime: the configs
# ../occcyl*_small_1xb1-12e_*-synthetic.py add one (SurroundOcc's or
# Occ3D's task file) and the CPU runtime, ../occcyl_tiny_* shrinks it for
# smoke tests. Every module of the paper's model at a fraction of its width
# and resolution (a finer cylinder and depth bins than the tiny config's,
# twice its widths, a GroupNorm image branch), trained from scratch with a
# warm-up and a cosine decay, sized so that 2 CPU cores train it in about
# an hour.
_base_ = ['../../_base_/datasets/nus-occ-common.py', './occcyl_r50-swins.py']

_img_channels = 32
_context_channels = 16
_point_channels = 16
_plane_channels = 32
_swin_dims = [32, 64, 128, 256]
# GroupNorm in the image branch, trained from scratch here: not in the
# paper, whose ImageNet-pretrained ResNet keeps its BN statistics frozen
# (norm_eval=True). A trained BN normalises each training step by the
# statistics of its 6 views, all of one scene, and the test by running
# means over the training scenes, which miss a held-out scene's weather
# and light. With BN, the trained occcyl-small-seg2d (second seed) scored
# 70.36 / 29.37 IoU / mIoU on the held-out scenes and 71.76 / 31.93 when
# the image branch normalised each test sample by its own statistics; an
# image branch trained on the 2-D semantic target alone (600 iterations)
# labelled 86.8 % of the training scenes' feature cells right with batch
# statistics, 54.1 % with the running ones. GN (8 groups) normalises each
# view by itself, alike in training and test: at 1664 iterations
# occcyl-small went from 67.96 / 27.22 to 71.87 / 32.49 and its ablation
# without depth supervision from 67.74 / 28.46 to 71.01 / 32.63 (seed 0).
_img_norm = dict(type='GN', num_groups=8)

model = dict(
    # 2.5 m bins (20 bins at 1, 3.5, ..., 48.5 m).
    depth_bound=[1.0, 51.0, 2.5],
    # 0.78 m x 2.8 degrees x 0.5 m cells. The tiny 32 x 64 cylinder smears
    # objects into 5.6-degree wedges (3.9 m of arc at 40 m): at the same
    # budget 64 x 128 x 16 scored 61.7 / 12.2 against 53.3 / 10.0 (IoU /
    # mIoU, the learning benchmark).
    cylinder=dict(shape=[64, 128, 16]),
    # No download: trained from scratch, so nothing frozen.
    pretrained=dict(
        img_backbone=dict(checkpoint=None),
        tpv_backbone=dict(checkpoint=None)),
    img_encoder=dict(
        backbone=dict(
            depth=18,
            base_channels=16,
            frozen_stages=-1,
            norm_eval=False,
            norm_cfg=_img_norm,
            # ResNet-18's basic blocks take no deformable conv.
            dcn=None,
            stage_with_dcn=(False, False, False, False),
            # A model this small needs no memory saving (nor do the modules
            # below): recomputation would only cost time.
            with_cp=False),
        neck=dict(in_channels=[16, 32, 64, 128], out_channels=_img_channels),
        neck_channels=_img_channels,
        out_channels=_img_channels,
        norm_cfg=_img_norm,
        with_cp=False),
    depth_net=dict(
        in_channels=_img_channels,
        mid_channels=_img_channels,
        context_channels=_context_channels,
        num_res_blocks=1,
        aspp_dilations=(1, 2),
        norm_cfg=_img_norm,
        with_cp=False),
    # Two layers in each point MLP, as the base's (the tiny config has
    # one).
    point_branch=dict(
        img_channels=_context_channels,
        geo_channels=(_point_channels, _point_channels),
        out_channels=(_point_channels, _point_channels)),
    tpv_fusion=dict(
        cam_channels=_context_channels,
        lidar_channels=_point_channels,
        plane_channels=_plane_channels,
        num_groups=4,  # M = 4
        with_cp=False),
    tpv_encoder=dict(
        backbone=dict(
            in_channels=_plane_channels,
            embed_dims=_swin_dims[0],
            depths=[1, 1, 1, 1],
            num_heads=[1, 2, 4, 8],  # 32-channel heads
            window_size=4,
            drop_path_rate=0.1,  # mmdet's default
            # Patch stride 1 (the base's is 2): the finest level keeps the
            # cylinder's 64 x 128 (R, Theta) cells. The paper config's
            # finest level (stride 2 of the 480 x 368 cylinder) has 0.21 m
            # x 2 degree cells, finer than the 0.5 m output; at stride 2
            # this cylinder's would be 1.56 m x 5.6 degrees (3.9 m of arc
            # at 40 m). Measured on the learning benchmark (seed 0, 60
            # CPU-minutes): 71.26 / 34.62 IoU / mIoU against 71.87 / 32.49
            # at stride 2 (pedestrian 17.6 against 10.1, motorcycle 13.1
            # against 7.5, truck 16.4 against 22.7). An iteration costs 5 %
            # more (paired timing); the run fit 1528 iterations in the
            # budget on a host shared by up to four runs, 1664 before.
            patch_size=1,
            strides=(1, 2, 2, 2),
            with_cp=False),
        neck=dict(in_channels=_swin_dims, out_channels=_plane_channels)),
    # The head's MLP as wide as the planes (the paper does not give its
    # width). Four times wider (128, TPVFormer's ratio of hidden to plane
    # width is 2) was no better on the learning benchmark (seed 0): 34.0
    # against 33.6 mIoU at 1100 iterations, and at the 60 CPU-minute limit
    # 71.4 / 34.5 IoU / mIoU after 1146 iterations against 71.26 / 34.62
    # after 1528: its MLP over the 640k voxels took 3.14 CPU-s an
    # iteration against 2.36 (both measured before the head projected
    # the planes ahead of sampling them).
    occ_head=dict(
        in_channels=_plane_channels,
        hidden_channels=_plane_channels,
        with_cp=False))
# The depth loss keeps the paper's weight 3 (eq. 19, from the base). With the
# BN image branch of before, it left the cameras no use in the benchmark's
# hour: mean images instead of the real ones scored the same (65.2 / 20.3
# against 65.1 / 20.1 IoU / mIoU), while at weight 0.3 the cameras added 2.2
# mIoU (66.4 / 24.4) and without the loss 6.4 (67.1 / 25.9); with GN the two
# tie (above), and at patch stride 1 too: two-seed means 71.71 / 33.94 with the
# loss, 72.11 / 34.20 without (seed 0 73.36 / 35.22 against 71.26 / 34.62, seed
# 1 70.87 / 33.18 against 72.17 / 33.26). At lr 4e-3 (below) the run without
# the loss scored higher in both seeds: 73.33 / 36.81 and 72.27 / 36.82 against
# 73.26 / 36.43 and 71.80 / 35.20 (means 72.80 / 36.82 against 72.53 / 35.81);
# see docs/reports/learning_benchmark.md. With 1.5x the iterations (2496, seed
# 0) the two tie: 74.17 / 38.04 with the loss, 74.12 / 38.22 without. The
# config keeps the paper's weight, the value its Table V measured on nuScenes;
# on the synthetic world the loss has not helped at any setting tried (see the
# BN numbers above).

# 192x320 images: a 12x20 feature map (the tiny config's is 6x10).
img_size = (192, 320)
# No BEV flips (the paper names no augmentation; SDG-OCC's configs keep
# them). With them the same 768 iterations scored 65.09 / 20.05 IoU /
# mIoU on the benchmark's held-out scenes, without them 65.71 / 25.57, and
# 1-sample fitting was slower (35.7 / 9.7 against 69.7 / 38.2 after 100
# iterations). Nor quarter turns (rot90=True): in the benchmark's hour
# the seg2d variant without depth supervision scored 37.48 and 36.27
# mIoU with them, 38.41 and 38.88 without.
# No photometric distortion either. MultiViewPhotoMetric after the resize
# (mmdet's ranges, as SurroundOcc's configs) was tried against the gap
# between training and held-out scenes (other flat 38.7 against 5.6 IoU at
# 1.5x the iterations) and did not move it: seed 0 tracked the curve of
# the run without it (31.7 against 31.0 mIoU at 900 iterations, 35.35
# against 35.3 at 1200, read off the report's curve; other flat 8.7 at the
# end), and seed 1 ended at 34.21 (other flat 13.7) after the 1204
# iterations its hour allowed on a slower host.
# The dataset base's pieces with these inputs; the configs put their label
# format's steps between them.
_larger = dict(MultiViewImageAug=dict(final_size=img_size))
_small_train_inputs = [
    dict(t, **_larger.get(t['type'], {})) for t in _base_.train_inputs
]
_small_test_inputs = [
    dict(t, **_larger.get(t['type'], {})) for t in _base_.test_inputs
]
_small_train_targets = [
    dict(t, flip_x_prob=0.0, flip_y_prob=0.0) if t['type'] == 'OccBEVAug'
    else t for t in _base_.train_targets
]
data_root = _base_._synthetic_root
train_dataloader = dict(
    **_base_._synthetic_loader, dataset=dict(data_root=data_root))
val_dataloader = test_dataloader = train_dataloader
ray_iou_metric = dict(data_root=data_root)

max_epochs = 12
train_cfg = dict(max_epochs=max_epochs, val_interval=max_epochs)
# Twice the tiny config's lr (2e-3), after a 50-iteration linear warm-up
# (without it the first iterations' loss rises at 64 x 128), decayed to 0
# by a cosine over the run. On the learning benchmark (60 CPU-minutes,
# 1531-1588 iterations) 4e-3 scored 73.26 / 36.43 and 71.80 / 35.20 IoU /
# mIoU (seeds 0 and 1) against 71.26 / 34.62 and 72.17 / 33.26 at 2e-3
# (truck 28.8 against 16.4 in seed 0); in the demo (144 iterations of the
# 3-scene world) 56.23 / 12.45 against 57.25 / 12.07. At 8e-3 training
# went unstable after the warm-up (seed 0: loss 20.1 at 100 iterations,
# 26.5 at 300, grad norms up to 101; held-out mIoU 12.5 at 100, 5.1 at
# 300, against 11.1 and 20.3 at 4e-3), and both seeds were stopped.
# From scratch, the image backbone learns at the full rate (the base's
# lr_mult 0.1 is for pretrained weights).
optim_wrapper = dict(
    optimizer=dict(lr=4e-3),
    paramwise_cfg=dict(
        custom_keys={'img_encoder.backbone': dict(lr_mult=1.0)}))
param_scheduler = [
    dict(type='LinearLR', start_factor=0.1, by_epoch=False, begin=0,
         end=50),
    dict(type='CosineAnnealingLR', by_epoch=True, begin=0,
         T_max=max_epochs, end=max_epochs, eta_min=0.0,
         convert_to_iter_based=True),
]
