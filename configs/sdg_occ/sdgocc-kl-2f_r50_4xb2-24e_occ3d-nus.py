# SDG-KL (Table 1's 50.16; not in Table 3, whose last row is SDG-Fusion) over
# T = 2 key frames: the two-frame camera BEV is the student, the teacher fuses
# it with the current LiDAR BEV. The model base's kl_model on
# sdgocc-fusion-2f_*.
_base_ = ['./sdgocc-fusion-2f_r50_4xb2-24e_occ3d-nus.py']

model = _base_.kl_model
