# Small OccCylindrical, synthetic 4-camera rig, no ring: customize_dataset.md
_base_ = ['./_base_/occcyl_small_nus-synthetic.py',
          '../_base_/datasets/surroundocc-task.py',
          '../_base_/cpu_smoke_runtime.py']

model = _base_.occ_task
cam_names, data_root = _base_._quad['cam_names'], _base_._quad['data_root']
train_pipeline, test_pipeline = [
    inputs + _base_._labels + targets + _base_._crop_and_pack
    for inputs, targets in [(_base_._small_train_inputs,
                             _base_._small_train_targets),
                            (_base_._small_test_inputs, _base_.test_targets)]]
_data = dict(_base_._occ_dataset, **_base_._quad)
train_dataloader = dict(dataset=dict(_data, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_data, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric
default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
