# SDG-OCC Table 3's Baseline row in FlashOcc M1's setting: the plain LSS
# lift, no LiDAR encoder, no fusion; predict needs no LiDAR points. Single
# frame without stereo, this is FlashOcc M1 (ResNet-50, 32.08 mIoU in
# FlashOcc's table). Table 3's 37.84 is FlashOcc M2, which adds 4D stereo
# over one adjacent frame: two-frame rows would need this repository's
# temporal machinery, and stereo is out of scope (issue 47). Without SDG
# nothing uses the 2D semantics, so the DepthNet has no semantic head and
# no loss_seg (FlashOcc has none); its depth supervision stays (FlashOcc's
# BEVDepth-style DepthNet has it).
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(
    variant='camera',
    lidar_encoder=None,
    fusion=None,
    view_transform=dict(use_sdg=False),
    depth_net=dict(seg_channels=0),
    loss_seg=None)
