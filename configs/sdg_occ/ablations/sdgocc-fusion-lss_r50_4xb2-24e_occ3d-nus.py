# SDG-OCC Table 3, "+FOAD" (44.92 mIoU): SDG-Fusion's LiDAR encoder and fusion
# on the plain LSS lift (no semantic diffusion, no virtual points). As in the
# Baseline row, nothing uses the 2D semantics without SDG: no semantic head, no
# loss_seg. (SDG + FOAD, 51.66, is the main SDG-Fusion config.)
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(
    view_transform=dict(use_sdg=False), depth_net=dict(seg_channels=0),
    loss_seg=None)
