# The toy config scored with RayIoU beside the voxel metric: every test
# sample casts its rays from two origins inside the 8 x 8 x 4 grid of
# 0.4 m voxels over [-1.6, 1.6] x [-1.6, 1.6] x [-0.8, 0.8]; label 0
# ('empty') is RayIoU's free label.
_base_ = ['./toy_occ.py']

test_dataloader = dict(
    dataset=dict(ray_origins=[[0.0, 0.0, 0.0], [0.6, -0.5, 0.1]]))
test_evaluator = [
    _base_.test_evaluator,
    dict(
        type='OccRayIoUMetric',
        class_names=_base_.class_names,
        free_index=0,
        pc_range=[-1.6, -1.6, -0.8, 1.6, 1.6, 0.8],
        voxel_size=0.4)
]
