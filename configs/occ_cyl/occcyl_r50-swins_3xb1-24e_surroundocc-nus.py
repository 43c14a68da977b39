# OccCylindrical (camera + LiDAR) on SurroundOcc-nuScenes as in the paper: the
# model, schedule and inputs of _base_/occcyl_r50-swins.py (1600x900 images,
# the key frame + 9 sweeps, the lineage's augmentation), 3 GPUs x 1 sample.
_base_ = ['../_base_/datasets/nus-occ-common.py',
          '../_base_/datasets/surroundocc-task.py',
          '../_base_/default_runtime.py', './_base_/occcyl_r50-swins.py']

model = _base_.occ_task
# The dataset base's pipelines around the labels, with the paper's inputs
# and the lineage's photometric-only training augmentation.
_inputs, _aug = _base_.paper_inputs, _base_.lineage_train_aug
img_size = _inputs.MultiViewImageAug.final_size
sweeps_num = _inputs.LoadOccPointsFromMultiSweeps.sweeps_num
train_pipeline = [
    step for t in _base_.train_inputs + _base_._labels + _base_.train_targets +
    _base_._crop_and_pack for step in
    [dict(t, **_inputs.get(t['type'], {}), **_aug.get(t['type'], {}))] +
    ([_base_.lineage_photometric] if t['type'] == 'MultiViewImageAug' else [])]
test_pipeline = [
    dict(t, **_inputs.get(t['type'], {})) for t in _base_.test_inputs +
    _base_._labels + _base_.test_targets + _base_._crop_and_pack]
train_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric
