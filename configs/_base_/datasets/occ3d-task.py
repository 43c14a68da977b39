# Occ3D-nuScenes' task (Tian et al., NeurIPS 2023): its grid, classes,
# label steps and metric, stated once. A config lists it beside
# nus-occ-common.py, assembles its pipelines from both (occ3d-nus.py is the
# dataset config on its own) and merges `occ_task` into its `model`.
occ_format = 'occ3d'
# The fixed grid: x, y in [-40, 40] m, z in [-1, 5.4] m, 0.4 m voxels, in
# the ego frame.
point_cloud_range = [-40.0, -40.0, -1.0, 40.0, 40.0, 5.4]
voxel_size = [0.4, 0.4, 0.4]
grid_size = [round((point_cloud_range[i + 3] - point_cloud_range[i]) /
                   voxel_size[i]) for i in range(3)]  # [200, 200, 16]
# 'others' (label 0), the 16 nuScenes-lidarseg classes (1..16), 'free' (17).
class_names = [
    'others', 'barrier', 'bicycle', 'bus', 'car', 'construction_vehicle',
    'motorcycle', 'pedestrian', 'traffic_cone', 'trailer', 'truck',
    'driveable_surface', 'other_flat', 'sidewalk', 'terrain', 'manmade',
    'vegetation', 'free']
num_classes = len(class_names)
empty_index = class_names.index('free')
# What every model config on this dataset merges into its `model` (the task
# arguments of the occupancy detectors): the grid, the classes, the empty
# label and, as the metric counts only camera-visible voxels, only those
# are supervised (BEVDet-Occ / FlashOcc's use_mask; neither paper says).
occ_task = dict(
    point_cloud_range=point_cloud_range, voxel_size=voxel_size,
    num_classes=num_classes, empty_index=empty_index,
    loss_mask_key='mask_camera')

_labels = [
    dict(type='LoadOccupancyGT', occ_format=occ_format),
    # Occ3D labels are in the ego frame: move points and cameras there, so
    # the ego frame is the working frame of everything after this step.
    dict(type='PointsToEgoFrame')]
_crop_and_pack = [
    dict(type='PointsRangeFilter', point_cloud_range=point_cloud_range),
    dict(type='PackOccInputs')]
_occ_dataset = dict(occ_format=occ_format, metainfo=dict(classes=class_names))
# Merged into nus-occ-common.py's OccupancyMetric: Occ3D's protocol counts
# only the voxels a camera sees; SDG-OCC Fig. 7 reports IoU by distance
# from the ego.
_occ_metric = dict(
    convention=occ_format, class_names=class_names, use_camera_mask=True,
    distance_ranges=[(0, 20), (20, 30), (30, 40)], voxel_size=voxel_size,
    point_cloud_range=point_cloud_range)
