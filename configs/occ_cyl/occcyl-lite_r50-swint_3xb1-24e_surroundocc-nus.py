# OccCylindrical, lighter (not the paper's size): the paper config with the
# slimmer widths shipped before the paper-size model (commit 81709f4,
# 2026-11-23), 65 M parameters instead of 111 M, for GPUs that do not hold
# the paper's model. The cylinder (Table VI), inputs and schedule are the
# paper config's; ResNet-50 stages 1-3 feed a 256-channel V, the DepthNet is
# 256 wide (BEVDepth's default) and the planes go through a Swin-T.
_base_ = ['./occcyl_r50-swins_3xb1-24e_surroundocc-nus.py']

_img_channels = 256
model = dict(
    img_encoder=dict(
        backbone=dict(out_indices=(1, 2, 3)),
        neck=dict(in_channels=[512, 1024, 2048], num_outs=3),
        num_levels=3, out_channels=_img_channels),
    depth_net=dict(in_channels=_img_channels, mid_channels=_img_channels),
    tpv_encoder=dict(
        # Swin-T's depths and drop-path rate (Swin paper, mmdet configs).
        backbone=dict(depths=[2, 2, 6, 2], drop_path_rate=0.2)),
    # ImageNet Swin-T weights for the Swin-T (as PointOcc).
    pretrained=dict(tpv_backbone=dict(checkpoint=(
        'https://github.com/SwinTransformer/storage/releases/download/v1.0.0/'
        'swin_tiny_patch4_window7_224.pth'))))
