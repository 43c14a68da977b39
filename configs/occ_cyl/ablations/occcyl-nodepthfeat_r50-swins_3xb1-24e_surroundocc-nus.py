# OccCylindrical Table V: without the depth feature, i.e. eq. 5 without
# CNN1(V_depth): V_context = V + CNN2(V_coord).
_base_ = ['../occcyl_r50-swins_3xb1-24e_surroundocc-nus.py']

model = dict(depth_net=dict(with_depth_feature=False))
