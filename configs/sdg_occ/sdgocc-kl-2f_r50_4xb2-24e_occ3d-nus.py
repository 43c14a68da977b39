# SDG-KL over T = 2 key frames (Table 3's last row as the paper ran its
# temporal models): the two-frame camera BEV is the student, the teacher
# fuses it with the current LiDAR BEV. The model base's kl_model on
# sdgocc-fusion-2f_*.
_base_ = ['./sdgocc-fusion-2f_r50_4xb2-24e_occ3d-nus.py']

model = _base_.kl_model
