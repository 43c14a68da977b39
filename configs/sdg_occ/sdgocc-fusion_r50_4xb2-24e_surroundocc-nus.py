# SDG-Fusion (SDG-OCC, Duan et al., CVPR 2025) on SurroundOcc-nuScenes: the
# model and schedule of _base_/sdgocc-fusion_r50.py on SurroundOcc's 100 m
# grid (LiDAR frame, 0.5 m voxels, 17 labels with 0 = empty, no camera
# mask), 256x704 images, 4 GPUs x 2 samples.
_base_ = [
    '../_base_/datasets/surroundocc-nus.py', '../_base_/default_runtime.py',
    './_base_/sdgocc-fusion_r50.py'
]

custom_imports = dict(
    imports=['projects.occ_common', 'projects.sdg_occ'],
    allow_failed_imports=False)

# The coupled values, from the dataset base, and the depth bins, LiDAR
# voxels and losses that suit its grid.
model = dict(
    _base_.occ_task,
    # Depth bins (not given by the paper): BEVDet's nuScenes 1..60 m at
    # 0.5 m (118 bins), which covers the 50 m grid along every camera axis.
    depth_bound=[1.0, 60.0, 0.5],
    # 0.125 m voxels instead of the Occ3D config's 0.1 m: two stride-2
    # stages take 0.125 m to the 0.5 m BEV cell, where 0.1 m would reach
    # 0.4 m.
    lidar_encoder=dict(voxel_size=[0.125, 0.125, 0.125]),
    # No camera mask here, so most voxels are empty: SurroundOcc's recipe of
    # cross-entropy plus the geometric and semantic scene-class affinity
    # losses (not fixed by the SDG-OCC paper).
    occ_head=dict(
        loss_occ=dict(losses=[
            dict(type='OccFocalLoss', gamma=0.0, loss_weight=1.0),
            dict(type='SceneClassAffinityLoss', mode='geo'),
            dict(type='SceneClassAffinityLoss', mode='sem'),
        ])))

# The pipelines with the 2-D semantic targets of SDG's image branch.
train_dataloader = dict(
    batch_size=2, dataset=dict(pipeline=_base_.train_pipeline_seg2d))
val_dataloader = dict(dataset=dict(pipeline=_base_.test_pipeline_seg2d))
test_dataloader = val_dataloader
