# OccCylindrical Table VI: depth interval d = 2 m (the paper's model uses
# 1 m): 25 bins at 1, 3, ..., 49 m, i.e. 6 x 25 x 58 x 100 pseudo points.
_base_ = ['../occcyl_r50-swint_3xb1-24e_surroundocc-nus.py']

custom_imports = dict(
    imports=['projects.occ_common', 'projects.occ_cyl'],
    allow_failed_imports=False)

depth_step = 2.0
depth_bound = [_base_.depth_bound[0], _base_.depth_bound[1], depth_step]
num_depth_bins = int(
    round((depth_bound[1] - depth_bound[0]) / depth_step))
model = dict(
    depth_bound=depth_bound,
    depth_net=dict(
        num_depth_bins=num_depth_bins,
        position_channels=3 * num_depth_bins),
    loss_depth=dict(depth_bound=depth_bound))
