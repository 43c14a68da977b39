# nuScenes + Occ3D-nuScenes occupancy labels (200x200x16, 0.4 m, ego frame).
# Prepare the data with (see projects/occ_common/datasets/README.md):
#   python tools/create_data.py nuscenes --root-path data/nuscenes \
#       --version v1.0-trainval
# For the synthetic world use occ3d-nus-synthetic.py (or override
# data_root). Everything below is derived from the values in this block.
custom_imports = dict(
    imports=['projects.occ_common'], allow_failed_imports=False)

data_root = 'data/nuscenes/'
info_prefix = 'nuscenes_occ'
occ_format = 'occ3d'
# Occ3D-nuScenes' fixed grid (Tian et al., NeurIPS 2023): x, y in
# [-40, 40] m, z in [-1, 5.4] m, 0.4 m voxels, in the ego frame.
point_cloud_range = [-40.0, -40.0, -1.0, 40.0, 40.0, 5.4]
voxel_size = [0.4, 0.4, 0.4]
# 'others' (label 0), the 16 nuScenes-lidarseg classes (1..16), 'free' (17).
class_names = [
    'others', 'barrier', 'bicycle', 'bus', 'car', 'construction_vehicle',
    'motorcycle', 'pedestrian', 'traffic_cone', 'trailer', 'truck',
    'driveable_surface', 'other_flat', 'sidewalk', 'terrain', 'manmade',
    'vegetation', 'free'
]
cam_names = [
    'CAM_FRONT', 'CAM_FRONT_RIGHT', 'CAM_FRONT_LEFT', 'CAM_BACK',
    'CAM_BACK_LEFT', 'CAM_BACK_RIGHT'
]
# Network input (H, W): BEVDet's 256x704 crop of the 900x1600 images.
img_size = (256, 704)
# nuScenes' usual 10 earlier sweeps (0.5 s of LiDAR at 20 Hz).
sweeps_num = 10

grid_size = [
    round((point_cloud_range[i + 3] - point_cloud_range[i]) / voxel_size[i])
    for i in range(3)
]  # [200, 200, 16]
num_classes = len(class_names)
dataset_type = 'NuScenesOccDataset'
backend_args = None

# Points carry x, y, z, intensity, time lag (the ring index of the files is
# replaced by the time lag when the sweeps are merged).
_load_points = [
    dict(
        type='LoadOccPointsFromFile',
        coord_type='LIDAR',
        load_dim=5,
        use_dim=5,
        backend_args=backend_args),
    # Needs nuScenes-lidarseg; without it drop this and PointsToSemanticMaps.
    dict(type='LoadLidarSegLabels', backend_args=backend_args),
]
train_pipeline = _load_points + [
    dict(
        type='LoadOccPointsFromMultiSweeps',
        sweeps_num=sweeps_num,
        load_dim=5,
        use_dim=[0, 1, 2, 3, 4],
        # The car's own body returns would otherwise fill the centre voxels.
        remove_close=True,
        backend_args=backend_args),
    dict(
        type='LoadMultiViewImagesOcc',
        cam_names=cam_names,
        backend_args=backend_args),
    # BEVDet's image augmentation: +-6 % scale, random horizontal crop,
    # flips and +-5.4 deg rotation.
    dict(
        type='MultiViewImageAug',
        final_size=img_size,
        resize_range=(0.94, 1.06),
        crop_x_range=(0.0, 1.0),
        crop_y_range=(1.0, 1.0),
        flip_prob=0.5,
        rot_range=(-5.4, 5.4)),
    dict(type='LoadOccupancyGT', occ_format=occ_format),
    # Occ3D labels are in the ego frame: move points and cameras there.
    dict(type='PointsToEgoFrame'),
    # Flips only: exact on the grid (other angles would resample labels).
    dict(type='OccBEVAug', flip_x_prob=0.5, flip_y_prob=0.5),
    dict(type='PointsToDepthMaps'),
    dict(type='PointsToSemanticMaps'),
    dict(type='PointsRangeFilter', point_cloud_range=point_cloud_range),
    dict(type='PackOccInputs'),
]
test_pipeline = _load_points + [
    dict(
        type='LoadOccPointsFromMultiSweeps',
        sweeps_num=sweeps_num,
        load_dim=5,
        use_dim=[0, 1, 2, 3, 4],
        remove_close=True,
        test_mode=True,
        backend_args=backend_args),
    dict(
        type='LoadMultiViewImagesOcc',
        cam_names=cam_names,
        backend_args=backend_args),
    dict(type='MultiViewImageAug', final_size=img_size, test_mode=True),
    dict(type='LoadOccupancyGT', occ_format=occ_format),
    dict(type='PointsToEgoFrame'),
    dict(type='OccBEVAug', test_mode=True),
    dict(type='PointsToDepthMaps'),
    dict(type='PointsToSemanticMaps'),
    dict(type='PointsRangeFilter', point_cloud_range=point_cloud_range),
    dict(type='PackOccInputs'),
]

_dataset = dict(
    type=dataset_type,
    data_root=data_root,
    occ_format=occ_format,
    cam_names=cam_names,
    metainfo=dict(classes=class_names),
    backend_args=backend_args)
train_dataloader = dict(
    batch_size=1,
    num_workers=4,
    persistent_workers=True,
    sampler=dict(type='DefaultSampler', shuffle=True),
    dataset=dict(
        _dataset,
        ann_file=f'{info_prefix}_infos_train.pkl',
        pipeline=train_pipeline,
        test_mode=False))
val_dataloader = dict(
    batch_size=1,
    num_workers=4,
    persistent_workers=True,
    drop_last=False,
    sampler=dict(type='DefaultSampler', shuffle=False),
    dataset=dict(
        _dataset,
        ann_file=f'{info_prefix}_infos_val.pkl',
        pipeline=test_pipeline,
        test_mode=True))
test_dataloader = val_dataloader

val_evaluator = dict(
    type='OccupancyMetric',
    convention=occ_format,
    class_names=class_names,
    # Occ3D's protocol: only voxels seen by a camera count.
    use_camera_mask=True,
    # OccCylindrical Tables II-III report rainy and night scenes.
    subsets=['rainy', 'night'],
    # SDG-OCC Fig. 7 reports IoU by distance from the ego.
    distance_ranges=[(0, 20), (20, 30), (30, 40)],
    voxel_size=voxel_size,
    point_cloud_range=point_cloud_range)
test_evaluator = val_evaluator
