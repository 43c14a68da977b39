# SDG-Fusion (SDG-OCC, Duan et al., CVPR 2025) on Occ3D-nuScenes: the model
# and schedule of _base_/sdgocc-fusion_r50.py on 256x704 images, 4 GPUs x 2
# samples, camera-mask mIoU.
_base_ = [
    '../_base_/datasets/occ3d-nus.py', '../_base_/default_runtime.py',
    './_base_/sdgocc-fusion_r50.py'
]

custom_imports = dict(
    imports=['projects.occ_common', 'projects.sdg_occ'],
    allow_failed_imports=False)

# The coupled values, from the dataset base (with Occ3D's camera mask on
# the loss, as FlashOcc's use_mask), and the depth bins that cover the grid.
model = dict(
    _base_.occ_task,
    # Depth bins of BEVDet-Occ / FlashOcc, which SDG-OCC builds on: 1..45 m
    # at 0.5 m (88 bins); the paper does not list them.
    depth_bound=[1.0, 45.0, 0.5])

# The pipelines with the 2-D semantic targets of SDG's image branch.
train_dataloader = dict(
    batch_size=2, dataset=dict(pipeline=_base_.train_pipeline_seg2d))
val_dataloader = dict(dataset=dict(pipeline=_base_.test_pipeline_seg2d))
test_dataloader = val_dataloader
