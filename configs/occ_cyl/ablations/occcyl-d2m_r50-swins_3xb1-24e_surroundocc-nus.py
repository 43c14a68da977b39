# OccCylindrical Table VI: depth interval d = 2 m (the paper's model uses
# 1 m): 25 bins at 1, 3, ..., 49 m, i.e. 6 x 25 x 58 x 100 pseudo points.
_base_ = ['../occcyl_r50-swins_3xb1-24e_surroundocc-nus.py']

# One key: DepthNet, position embedding and depth loss take it from here.
model = dict(depth_bound=[*_base_.model.depth_bound[:2], 2.0])
