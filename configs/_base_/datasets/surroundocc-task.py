# SurroundOcc-nuScenes' task (Wei et al., ICCV 2023): its grid, classes,
# label step and metric, stated once. A config lists it beside
# nus-occ-common.py, assembles its pipelines from both (surroundocc-nus.py
# is the dataset config on its own) and merges `occ_task` into its `model`.
occ_format = 'surroundocc'
# SurroundOcc's fixed grid: x, y in [-50, 50] m, z in [-5, 3] m, 0.5 m
# voxels, in the LiDAR frame.
point_cloud_range = [-50.0, -50.0, -5.0, 50.0, 50.0, 3.0]
voxel_size = [0.5, 0.5, 0.5]
grid_size = [round((point_cloud_range[i + 3] - point_cloud_range[i]) /
                   voxel_size[i]) for i in range(3)]  # [200, 200, 16]
# 'empty' (label 0) then the 16 nuScenes-lidarseg classes (labels 1..16).
class_names = [
    'empty', 'barrier', 'bicycle', 'bus', 'car', 'construction_vehicle',
    'motorcycle', 'pedestrian', 'traffic_cone', 'trailer', 'truck',
    'driveable_surface', 'other_flat', 'sidewalk', 'terrain', 'manmade',
    'vegetation']
num_classes = len(class_names)
empty_index = class_names.index('empty')
# What every model config on this dataset merges into its `model` (the task
# arguments of the occupancy detectors): the grid, the classes and the empty
# label. SurroundOcc has no visibility mask: every voxel is supervised.
occ_task = dict(
    point_cloud_range=point_cloud_range, voxel_size=voxel_size,
    num_classes=num_classes, empty_index=empty_index)

_labels = [dict(type='LoadOccupancyGT', occ_format=occ_format)]
_crop_and_pack = [
    dict(type='PointsRangeFilter', point_cloud_range=point_cloud_range),
    dict(type='PackOccInputs')]
_occ_dataset = dict(occ_format=occ_format, metainfo=dict(classes=class_names))
# Merged into nus-occ-common.py's OccupancyMetric: no visibility mask;
# SDG-OCC Fig. 7 reports IoU by distance from the ego.
_occ_metric = dict(
    convention=occ_format, class_names=class_names, use_camera_mask=False,
    distance_ranges=[(0, 20), (20, 30), (30, 40), (40, 50)],
    voxel_size=voxel_size, point_cloud_range=point_cloud_range)
