# OccCylindrical Table VII: spatial group pooling with M = 2 groups (the
# paper's model uses M = 8).
_base_ = ['../occcyl_r50-swint_3xb1-24e_surroundocc-nus.py']

custom_imports = dict(
    imports=['projects.occ_common', 'projects.occ_cyl'],
    allow_failed_imports=False)

num_groups = 2
model = dict(tpv_fusion=dict(num_groups=num_groups))
