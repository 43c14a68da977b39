# SDG-Fusion (SDG-OCC, Duan et al., CVPR 2025) on Occ3D-nuScenes: the model
# and schedule of _base_/sdgocc-fusion_r50.py on 256x704 images, 4 GPUs x 2
# samples, camera-mask mIoU (also on the loss, as FlashOcc's use_mask).
_base_ = ['../_base_/datasets/nus-occ-common.py',
          '../_base_/datasets/occ3d-task.py', '../_base_/default_runtime.py',
          './_base_/sdgocc-fusion_r50.py']

model = dict(_base_.occ_task, depth_bound=_base_.depth_bounds.occ3d)
# The pipelines with the 2-D semantic targets of SDG's image branch.
train_pipeline = (
    _base_.train_inputs_seg2d + _base_._labels + _base_.train_targets_seg2d +
    _base_._crop_and_pack)
test_pipeline = (
    _base_.test_inputs_seg2d + _base_._labels + _base_.test_targets_seg2d +
    _base_._crop_and_pack)
train_dataloader = dict(
    batch_size=2, dataset=dict(_base_._occ_dataset, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric
