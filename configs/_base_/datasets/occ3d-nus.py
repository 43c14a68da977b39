# nuScenes with Occ3D-nuScenes labels as one dataset config (for the data
# tools and tests; the model configs assemble the same pieces themselves):
# nus-occ-common.py around occ3d-task.py's label steps.
_base_ = ['./nus-occ-common.py', './occ3d-task.py']

custom_imports = dict(imports=['projects.occ_common'],
                      allow_failed_imports=False)
# The plain pipelines (OccCylindrical's) and those with SDG-OCC's 2-D
# semantic targets (gt_seg_2d).
train_pipeline, test_pipeline, train_pipeline_seg2d, test_pipeline_seg2d = [
    inputs + _base_._labels + targets + _base_._crop_and_pack
    for inputs, targets in [
        (_base_.train_inputs, _base_.train_targets),
        (_base_.test_inputs, _base_.test_targets),
        (_base_.train_inputs_seg2d, _base_.train_targets_seg2d),
        (_base_.test_inputs_seg2d, _base_.test_targets_seg2d)]]
train_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric
