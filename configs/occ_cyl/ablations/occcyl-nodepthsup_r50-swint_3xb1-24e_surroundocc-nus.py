# OccCylindrical Table V: without LiDAR depth supervision (no depth loss;
# the depth distribution is learnt through the occupancy loss only).
_base_ = ['../occcyl_r50-swint_3xb1-24e_surroundocc-nus.py']

custom_imports = dict(
    imports=['projects.occ_common', 'projects.occ_cyl'],
    allow_failed_imports=False)

model = dict(loss_depth=None)
