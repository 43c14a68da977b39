# OccCylindrical Table VI: depth interval d = 10 m (the paper's model uses
# 1 m): 5 bins at 1, 11, 21, 31, 41 m, i.e. 6 x 5 x 58 x 100 pseudo points.
_base_ = ['../occcyl_r50-swins_3xb1-24e_surroundocc-nus.py']

# One key: DepthNet, the position embedding and the depth loss take their
# bins from the detector's depth_bound.
model = dict(depth_bound=[*_base_.model.depth_bound[:2], 10.0])
