# The tiny SDG-Fusion of the CPU configs (sdgocc-*_tiny_* and, with sweeps
# and a longer schedule, sdgocc-*_small_*): every module of the full model
# at a fraction of its width, trained from scratch, for smoke tests, the
# demo and the learning benchmark. Their bases (./sdgocc-fusion_{tiny,small}
# _occ3d-nus-synthetic.py) merge `tiny_model` into the model base's.

# Small widths so that a CPU iteration takes about a second.
_tiny_img_channels = _tiny_bev_channels = 32
_tiny_cam_channels = _tiny_lidar_channels = 16
tiny_model = dict(
    img_backbone=dict(
        depth=18, base_channels=8, norm_eval=True,
        # A tiny model needs no memory saving (nor do the modules below):
        # recomputation would only cost time.
        with_cp=False),
    pretrained=None,  # no download: trained from scratch
    point_seg_head=None,
    img_neck=dict(in_channels=[32, 64], out_channels=_tiny_img_channels),
    depth_net=dict(
        in_channels=_tiny_img_channels, mid_channels=_tiny_img_channels,
        context_channels=_tiny_cam_channels, num_res_blocks=1,
        aspp_dilations=(), with_cp=False),
    # One voxel per BEV cell (the bases set voxel_size to the grid's): no
    # down-sampling keeps the sparse convs cheap on CPU.
    lidar_encoder=dict(
        base_channels=8,
        stage_channels=(_tiny_lidar_channels, _tiny_lidar_channels),
        stage_strides=(1, 1), out_channels=_tiny_lidar_channels,
        with_cp=False),
    fusion=dict(embed_dims=16, num_heads=2, num_layers=1),
    bev_encoder=dict(
        in_channels=_tiny_cam_channels,
        stage_channels=[_tiny_cam_channels * 2, _tiny_cam_channels * 4],
        num_blocks=[1, 1], out_channels=_tiny_bev_channels),
    occ_head=dict(
        in_channels=_tiny_bev_channels, mid_channels=_tiny_bev_channels,
        # Departure for a short CPU budget: FlashOcc's masked cross-entropy
        # alone collapses to "ground and free" (IoU 62.08, mIoU 6.4 after
        # 200 iterations; 2.3 % of the visible voxels are occupied); Lovasz
        # and scene-class affinity (OccCylindrical's eq. 18 set) optimise
        # per-class IoU directly.
        loss_occ=dict(losses=[
            dict(type='OccFocalLoss', gamma=0.0), dict(type='OccLovaszLoss'),
            dict(type='SceneClassAffinityLoss', mode='geo'),
            dict(type='SceneClassAffinityLoss', mode='sem')])))
tiny_depth_step = 1.0  # 1 m bins (full: 0.5 m) halve the LSS fallback's points
tiny_img_size = (128, 352)  # half the paper's 256x704 per side
# lr 2e-3 (20x the paper's): a from-scratch tiny model on a few samples.
tiny_optim_wrapper = dict(optimizer=dict(lr=2e-3))
