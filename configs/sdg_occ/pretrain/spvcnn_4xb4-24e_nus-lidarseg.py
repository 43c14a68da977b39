# SDG-OCC's release starts SPVCNN from a lidarseg training (not in the
# paper). This trains the SDG encoder (no BEV projection) on the key frames'
# lidarseg labels (sweeps unlabelled), Occ3D's ego frame; its checkpoint is
# then the SDG configs' model.pretrained.lidar_encoder.checkpoint.
_base_ = ['../../_base_/datasets/nus-occ-common.py',
          '../../_base_/datasets/occ3d-task.py',
          '../../_base_/default_runtime.py', '../_base_/sdgocc-fusion_r50.py']

model = dict(
    _delete_=True, type='SPVCNNSegmentor',
    data_preprocessor=dict(type='Det3DDataPreprocessor'),
    lidar_encoder=dict(_base_.model.lidar_encoder, bev_output=False,
                       point_cloud_range=_base_.point_cloud_range),
    point_seg_head=dict(_base_.model.point_seg_head, loss_weight=1.0))
train_pipeline = [
    _base_._key_frame, dict(_base_._lidarseg, optional=False),
    _base_._remove_ego, _base_._sweeps, dict(type='PointsToEgoFrame'),
    dict(type='OccBEVAug', flip_x_prob=0.5, flip_y_prob=0.5),
    dict(type='PointsRangeFilter', point_cloud_range=_base_.point_cloud_range),
    dict(type='PackOccInputs', keys=['points', 'pts_semantic_mask'])]
train_dataloader = dict(
    batch_size=4, dataset=dict(_base_._occ_dataset, pipeline=train_pipeline))
val_dataloader = test_dataloader = val_evaluator = test_evaluator = None
val_cfg = test_cfg = None
# Schedule unpublished: the detector's at 10x the rate, cosine decay.
optim_wrapper = dict(optimizer=dict(lr=1e-3))
param_scheduler = _base_.param_scheduler + [dict(
    type='CosineAnnealingLR', by_epoch=True, T_max=_base_.max_epochs,
    eta_min=0.0, convert_to_iter_based=True)]
auto_scale_lr = dict(base_batch_size=16)
