# SDG-KL on Occ3D-nuScenes: SDG-Fusion's network with the fusion as teacher
# (kl_model of _base_/sdgocc-fusion_r50.py); camera-only inference.
_base_ = ['./sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = _base_.kl_model
