# OccCylindrical trained with the dataset base's geometric augmentation
# (../../_base_/datasets/nus-occ-common.py: per-view resize, crop, flip and
# rotation, random BEV flips) instead of the lineage's photometric one
# (the model base's lineage_train_aug says why the paper config has none).
# Not a paper ablation: the option for users who want it.
_base_ = ['../occcyl_r50-swins_3xb1-24e_surroundocc-nus.py']

_geometric = {
    t['type']: t
    for t in _base_.train_inputs + _base_.train_targets
    if t['type'] in ('MultiViewImageAug', 'OccBEVAug')}
train_pipeline = [
    dict(_geometric[t['type']], final_size=_base_.img_size)
    if t['type'] == 'MultiViewImageAug' else _geometric.get(t['type'], t)
    for t in _base_.train_pipeline if t['type'] != 'MultiViewPhotoMetric']
train_dataloader = dict(dataset=dict(pipeline=train_pipeline))
