# OccCylindrical Table VII: spatial group pooling with M = 1 group, i.e.
# plain max pooling along each axis (the paper's model uses M = 8).
_base_ = ['../occcyl_r50-swins_3xb1-24e_surroundocc-nus.py']

model = dict(tpv_fusion=dict(num_groups=1))
