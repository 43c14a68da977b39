# SDG-OCC Table 3, Baseline (37.84 mIoU, FlashOcc's camera-only R50 model):
# the plain LSS lift, no LiDAR encoder, no fusion; predict needs no LiDAR
# points. Without SDG nothing uses the 2D semantics, so the DepthNet has no
# semantic head and no loss_seg (FlashOcc has none); its depth supervision
# stays (FlashOcc's BEVDepth-style DepthNet has it).
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(
    variant='camera',
    lidar_encoder=None,
    fusion=None,
    view_transform=dict(use_sdg=False),
    depth_net=dict(seg_channels=0),
    loss_seg=None)
