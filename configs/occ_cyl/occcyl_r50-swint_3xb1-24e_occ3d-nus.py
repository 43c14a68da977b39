# OccCylindrical (camera + LiDAR) on Occ3D-nuScenes: the paper's model and
# schedule (_base_/occcyl_r50-swint.py) on Occ3D's grid, 18 classes
# (17 = free), the ego frame and the camera-mask metric; 1600x900 images.
_base_ = [
    '../_base_/datasets/occ3d-nus.py', '../_base_/default_runtime.py',
    './_base_/occcyl_r50-swint.py'
]

custom_imports = dict(
    imports=['projects.occ_common', 'projects.occ_cyl'],
    allow_failed_imports=False)

# The coupled values, from the dataset base (with Occ3D's camera mask on
# the loss; the paper does not say).
model = _base_.occ_task

# The dataset base crops to BEVDet's 256x704; the paper feeds 1600x900.
img_size = (900, 1600)
_full_size = dict(MultiViewImageAug=dict(final_size=img_size))
train_pipeline = [
    dict(t, **_full_size.get(t['type'], {})) for t in _base_.train_pipeline
]
test_pipeline = [
    dict(t, **_full_size.get(t['type'], {})) for t in _base_.test_pipeline
]
train_dataloader = dict(dataset=dict(pipeline=train_pipeline))
val_dataloader = dict(dataset=dict(pipeline=test_pipeline))
test_dataloader = val_dataloader
