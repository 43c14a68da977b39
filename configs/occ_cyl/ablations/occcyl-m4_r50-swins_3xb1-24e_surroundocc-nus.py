# OccCylindrical Table VII: spatial group pooling with M = 4 groups (the
# paper's model uses M = 8).
_base_ = ['../occcyl_r50-swins_3xb1-24e_surroundocc-nus.py']

model = dict(tpv_fusion=dict(num_groups=4))
