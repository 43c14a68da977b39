# OccCylindrical Table V: without the depth feature, i.e. eq. 5 without
# CNN1(V_depth): V_context = V + CNN2(V_coord).
_base_ = ['../occcyl_r50-swint_3xb1-24e_surroundocc-nus.py']

custom_imports = dict(
    imports=['projects.occ_common', 'projects.occ_cyl'],
    allow_failed_imports=False)

model = dict(depth_net=dict(with_depth_feature=False))
