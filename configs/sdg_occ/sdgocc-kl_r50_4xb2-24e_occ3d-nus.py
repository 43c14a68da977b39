# SDG-KL on Occ3D-nuScenes: SDG-Fusion's network trained with the fusion as
# a teacher and FOAD distillation into the camera BEV (kl_model of
# _base_/sdgocc-fusion_r50.py); inference skips the LiDAR branch and fusion.
_base_ = ['./sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = _base_.kl_model
