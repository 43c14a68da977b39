# SDG-Fusion (SDG-OCC, Duan et al., CVPR 2025) on SurroundOcc-nuScenes: the
# model and schedule of _base_/sdgocc-fusion_r50.py on SurroundOcc's 100 m
# grid (LiDAR frame, 0.5 m voxels, 17 labels with 0 = empty, no camera
# mask), 256x704 images, 4 GPUs x 2 samples.
_base_ = ['../_base_/datasets/nus-occ-common.py',
          '../_base_/datasets/surroundocc-task.py',
          '../_base_/default_runtime.py', './_base_/sdgocc-fusion_r50.py']

model = dict(
    _base_.occ_task,
    depth_bound=_base_.depth_bounds.surroundocc,
    # 0.125 m voxels instead of the Occ3D config's 0.1 m: two stride-2
    # stages take them to the 0.5 m BEV cell (0.1 m would reach 0.4 m).
    lidar_encoder=dict(voxel_size=[0.125, 0.125, 0.125]),
    # No camera mask here, so most voxels are empty: SurroundOcc's recipe of
    # cross-entropy plus the geometric and semantic scene-class affinity
    # losses (not fixed by the SDG-OCC paper).
    occ_head=dict(
        loss_occ=dict(losses=[
            dict(type='OccFocalLoss', gamma=0.0, loss_weight=1.0),
            dict(type='SceneClassAffinityLoss', mode='geo'),
            dict(type='SceneClassAffinityLoss', mode='sem')])))
# The pipelines with the 2-D semantic targets of SDG's image branch.
train_pipeline = (
    _base_.train_inputs_seg2d + _base_._labels + _base_.train_targets_seg2d +
    _base_._crop_and_pack)
test_pipeline = (
    _base_.test_inputs_seg2d + _base_._labels + _base_.test_targets_seg2d +
    _base_._crop_and_pack)
train_dataloader = dict(
    batch_size=2, dataset=dict(_base_._occ_dataset, pipeline=train_pipeline))
val_dataloader = test_dataloader = dict(
    dataset=dict(_base_._occ_dataset, pipeline=test_pipeline))
val_evaluator = test_evaluator = _base_._occ_metric
