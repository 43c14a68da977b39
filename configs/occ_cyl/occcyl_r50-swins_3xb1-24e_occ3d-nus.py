# OccCylindrical (camera + LiDAR) on Occ3D-nuScenes: the paper's model and
# schedule (_base_/occcyl_r50-swins.py) on Occ3D's grid, 18 classes
# (17 = free), the ego frame and the camera-mask metric; 1600x900 images,
# the key frame + 9 sweeps.
_base_ = [
    '../_base_/datasets/occ3d-nus.py', '../_base_/default_runtime.py',
    './_base_/occcyl_r50-swins.py'
]

custom_imports = dict(
    imports=['projects.occ_common', 'projects.occ_cyl'],
    allow_failed_imports=False)

# The coupled values, from the dataset base (with Occ3D's camera mask on
# the loss; the paper does not say).
model = _base_.occ_task

# The dataset base crops to BEVDet's 256x704; the paper feeds 1600x900.
img_size = (900, 1600)
# "10 LiDAR sweeps": the authors' OccFusion code loads the key frame and 9
# sweeps (LoadPointsFromMultiSweeps(sweeps_num=9)), 10 frames in all.
sweeps_num = 9
_paper_inputs = dict(
    MultiViewImageAug=dict(final_size=img_size),
    LoadOccPointsFromMultiSweeps=dict(sweeps_num=sweeps_num))
# The lineage's photometric-only augmentation (the model base says why).
_train_aug = _base_.lineage_train_aug
train_pipeline = [
    step for t in _base_.train_pipeline for step in
    [dict(t, **_paper_inputs.get(t['type'], {}),
          **_train_aug.get(t['type'], {}))] +
    ([_base_.lineage_photometric] if t['type'] == 'MultiViewImageAug' else [])
]
test_pipeline = [
    dict(t, **_paper_inputs.get(t['type'], {}))
    for t in _base_.test_pipeline
]
train_dataloader = dict(dataset=dict(pipeline=train_pipeline))
val_dataloader = dict(dataset=dict(pipeline=test_pipeline))
test_dataloader = val_dataloader
