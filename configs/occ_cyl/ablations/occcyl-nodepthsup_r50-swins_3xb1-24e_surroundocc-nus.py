# OccCylindrical Table V: without LiDAR depth supervision (no depth loss;
# the depth distribution is learnt through the occupancy loss only).
_base_ = ['../occcyl_r50-swins_3xb1-24e_surroundocc-nus.py']

model = dict(loss_depth=None)
