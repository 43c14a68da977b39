# SDG-OCC Table 3, "+FOAD" (44.92 mIoU): SDG-Fusion's LiDAR encoder and fusion
# on the plain LSS lift (lss_lift_model: no semantic diffusion, no virtual
# points, no semantic head). Table 3's last row, SDG + FOAD (51.66), is the
# main SDG-Fusion config; SDG-KL is not in Table 3 (Table 1: 50.16).
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = _base_.lss_lift_model
