# The small OccCylindrical of the held-out learning benchmark
# (_base_/occcyl_small_nus-synthetic.py) on the synthetic world's
# SurroundOcc labels.
_base_ = ['./_base_/occcyl_small_nus-synthetic.py',
          '../_base_/datasets/surroundocc-task.py',
          '../_base_/cpu_smoke_runtime.py']

model = _base_.occ_task
train_pipeline = (
    _base_._small_train_inputs + _base_._labels +
    _base_._small_train_targets + _base_._crop_and_pack)
test_pipeline = (
    _base_._small_test_inputs + _base_._labels + _base_.test_targets +
    _base_._crop_and_pack)
train_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric
default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
