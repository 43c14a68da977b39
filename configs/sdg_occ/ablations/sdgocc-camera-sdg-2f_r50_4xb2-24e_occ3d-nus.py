# SDG-OCC Table 3's "+SDG" row over T = 2 key frames: sdgocc-camera-sdg_*'s
# camera branch (camera_sdg_model) on the two-frame SDG-Fusion
# (../sdgocc-fusion-2f_*). Each frame's SDG lift reads that frame's LiDAR
# points, so the previous key frames load theirs.
_base_ = ['../sdgocc-fusion-2f_r50_4xb2-24e_occ3d-nus.py']

model = _base_.camera_sdg_model
