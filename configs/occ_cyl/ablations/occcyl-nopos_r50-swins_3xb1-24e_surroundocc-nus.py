# OccCylindrical Table V: without the cylindrical position embedding, i.e.
# eq. 5 without CNN2(V_coord): V_context = V + CNN1(V_depth).
_base_ = ['../occcyl_r50-swins_3xb1-24e_surroundocc-nus.py']

model = dict(depth_net=dict(position_channels=0))
