# What every nuScenes occupancy config shares: cameras, sweeps, loaders,
# image augmentation, dataloaders and metrics. Not a config on its own: a
# config adds a label format (occ3d-task.py or surroundocc-task.py) and
# assembles its pipelines from both, as occ3d-nus.py does (a base's values
# are fixed when it is read, so what needs both is built where both are
# listed). Prepare the data with (docs/dataset_prepare.md):
#   python tools/create_data.py nuscenes --root-path data/nuscenes \
#       --version v1.0-trainval
data_root = 'data/nuscenes/'
info_prefix = 'nuscenes_occ'
cam_names = ['CAM_FRONT', 'CAM_FRONT_RIGHT', 'CAM_FRONT_LEFT', 'CAM_BACK',
             'CAM_BACK_LEFT', 'CAM_BACK_RIGHT']
img_size = (256, 704)  # network input (H, W): BEVDet's crop of 900x1600
sweeps_num = 10  # nuScenes' usual 10 earlier sweeps (0.5 s at 20 Hz)
dataset_type = 'NuScenesOccDataset'
backend_args = None

# The ego vehicle (x0, y0, z0, x1, y1, z1), the nuScenes Renault Zoe with a
# margin (projects/occ_common/transforms/ego_points.py): its own returns (a
# quarter of a key frame, in voxels labelled empty) go from every sweep.
ego_box = [-0.9, -1.1, -0.5, 3.7, 1.1, 2.2]
# x, y, z, intensity of the info file's point layout, then the time lag.
_key_frame = dict(type='LoadOccPointsFromFile', coord_type='LIDAR',
                  load_dim=None, use_dim=4, backend_args=backend_args)
_remove_ego = dict(type='RemoveEgoPoints', ego_box=ego_box)
# nuScenes-lidarseg point labels, for SDG-OCC's 2-D semantic targets only
# (PointsToSemanticMaps): loaded where the info file has them, else those
# targets come from the occupancy labels.
_lidarseg = dict(
    type='LoadLidarSegLabels', optional=True, backend_args=backend_args)
# The box, not mmdet3d's remove_close (a 1 m sphere that misses the bonnet).
_sweeps = dict(
    type='LoadOccPointsFromMultiSweeps', sweeps_num=sweeps_num,
    load_dim=None, ego_box=ego_box, backend_args=backend_args)
_images = dict(type='LoadMultiViewImagesOcc', backend_args=backend_args)
# Up to the labels: points, sweeps, images and (training) BEVDet's image
# augmentation: +-6 % scale, random horizontal crop, flips, +-5.4 deg rotation.
train_inputs = [
    _key_frame, _remove_ego, _sweeps, _images,
    dict(type='MultiViewImageAug', final_size=img_size,
         resize_range=(0.94, 1.06), crop_x_range=(0.0, 1.0),
         crop_y_range=(1.0, 1.0), flip_prob=0.5, rot_range=(-5.4, 5.4))]
test_inputs = [
    _key_frame, _remove_ego, dict(_sweeps, test_mode=True), _images,
    dict(type='MultiViewImageAug', final_size=img_size, test_mode=True)]
# After the labels: BEV flips only (exact on the grid; other angles would
# resample labels), then the depth and 2D semantic targets of the cameras.
train_targets = [dict(type='OccBEVAug', flip_x_prob=0.5, flip_y_prob=0.5),
                 dict(type='PointsToDepthMaps')]
test_targets = [dict(type='OccBEVAug', test_mode=True),
                dict(type='PointsToDepthMaps')]
# The same with SDG-OCC's 2-D semantic targets (the lidarseg labels are
# loaded before the ego points go, so that they stay aligned).
train_inputs_seg2d = [_key_frame, _lidarseg] + train_inputs[1:]
test_inputs_seg2d = [_key_frame, _lidarseg] + test_inputs[1:]
train_targets_seg2d = train_targets + [dict(type='PointsToSemanticMaps')]
test_targets_seg2d = test_targets + [dict(type='PointsToSemanticMaps')]

# The dataloaders, without the label format's keys and the pipelines. A
# paper config's pipeline costs 0.27-0.35 s of one CPU core a real key frame
# (tools/analysis_tools/benchmark_data.py --real-sample, docs/model_zoo.md)
# against 0.6-2.1 s a GPU step: 4 workers leave room for AMP, real sweeps
# and a cold disk; pinned memory lets the copy to the GPU run async.
_loader = dict(
    batch_size=1, num_workers=4, persistent_workers=True, pin_memory=True)
_dataset = dict(type=dataset_type, data_root=data_root, cam_names=cam_names,
                backend_args=backend_args)
train_dataloader = dict(
    _loader, sampler=dict(type='DefaultSampler', shuffle=True),
    dataset=dict(
        _dataset, ann_file=f'{info_prefix}_infos_train.pkl', test_mode=False))
val_dataloader = test_dataloader = dict(
    _loader, drop_last=False,
    sampler=dict(type='DefaultSampler', shuffle=False),
    dataset=dict(
        _dataset, ann_file=f'{info_prefix}_infos_val.pkl', test_mode=True))

# OccCylindrical Tables II-III report rainy and night scenes.
val_evaluator = test_evaluator = dict(
    type='OccupancyMetric', subsets=['rainy', 'night'])
# RayIoU (SparseOcc, Liu et al., ECCV 2024) of Occ3D labels, scored by the
# *-nomask*.py configs beside the voxel metric: mIoU with the camera mask
# rewards thick surfaces and training with the mask inflates it, so
# SparseOcc trains without it for a fair RayIoU. Rays start at every key
# frame of the scene, whose poses come from the split's info file.
ray_iou_metric = dict(
    type='OccRayIoUMetric', data_root=data_root,
    ann_file=val_dataloader['dataset']['ann_file'])

# The synthetic nuScenes-format world of the CPU configs; build it with
#   python tools/dataset_converters/create_synthetic_nuscenes.py \
#       data/nuscenes_synthetic
#   python tools/create_data.py nuscenes --root-path data/nuscenes_synthetic \
#       --version v1.0-mini
# (the converter splits the world's last scenes off as val). On CPU, workers
# only add start-up time on a few samples; there is no device memory to pin.
_synthetic_root = 'data/nuscenes_synthetic/'
_synthetic_loader = dict(
    num_workers=0, persistent_workers=False, pin_memory=False)
# Its four-camera rig (create_synthetic_nuscenes.py --camera-rig quad ...)
_quad = dict(data_root='data/nuscenes_synthetic_quad/',
             cam_names=['CAM_FRONT', 'CAM_LEFT', 'CAM_BACK', 'CAM_RIGHT'])
