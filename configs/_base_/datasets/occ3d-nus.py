# nuScenes + Occ3D-nuScenes occupancy labels (200x200x16, 0.4 m, ego frame)
# as one dataset config (the data tools and the dataset tests load it): the
# pieces of nus-occ-common.py around the label steps of occ3d-task.py. The
# model configs assemble the same pieces themselves (bases stay flat, so a
# config plus its bases is at most three files). For the synthetic world
# override data_root.
_base_ = ['./nus-occ-common.py', './occ3d-task.py']

custom_imports = dict(
    imports=['projects.occ_common'], allow_failed_imports=False)
train_pipeline = (
    _base_.train_inputs + _base_._labels + _base_.train_targets +
    _base_._crop_and_pack)
test_pipeline = (
    _base_.test_inputs + _base_._labels + _base_.test_targets +
    _base_._crop_and_pack)
# With the 2-D semantic targets (gt_seg_2d) of SDG-OCC.
train_pipeline_seg2d = (
    _base_.train_inputs_seg2d + _base_._labels + _base_.train_targets_seg2d +
    _base_._crop_and_pack)
test_pipeline_seg2d = (
    _base_.test_inputs_seg2d + _base_._labels + _base_.test_targets_seg2d +
    _base_._crop_and_pack)
train_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric
