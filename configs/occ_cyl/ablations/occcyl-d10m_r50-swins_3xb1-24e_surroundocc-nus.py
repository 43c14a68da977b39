# OccCylindrical Table VI: depth interval d = 10 m (the paper's model uses
# 1 m): 5 bins at 1, 11, 21, 31, 41 m, i.e. 6 x 5 x 58 x 100 = 174,000
# pseudo points, Table VI's count. The paper puts its model's farthest bin
# at 50 m but does not say where d = 10 m starts; keeping the base's depth
# range [1, 51) and step 10 is a choice: bins at 10..50 would need that
# range moved to [10, 60) and the depth loss supervising up to 60 m.
_base_ = ['../occcyl_r50-swins_3xb1-24e_surroundocc-nus.py']

# One key: DepthNet, position embedding and depth loss take it from here.
model = dict(depth_bound=[*_base_.model.depth_bound[:2], 10.0])
