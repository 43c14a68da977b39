# Occ3D-nuScenes' task (Tian et al., NeurIPS 2023): its grid, classes,
# labels and metric settings, stated once. occ3d-nus.py builds its
# pipelines and metric from them; a config whose base chain already carries
# another dataset switches to Occ3D through this file, which adds only the
# key `occ3d` (mmengine refuses a key that two bases both define).
occ3d = dict(
    occ_format='occ3d',
    # The fixed grid: x, y in [-40, 40] m, z in [-1, 5.4] m, 0.4 m voxels,
    # in the ego frame (200 x 200 x 16).
    point_cloud_range=[-40.0, -40.0, -1.0, 40.0, 40.0, 5.4],
    voxel_size=[0.4, 0.4, 0.4],
    # 'others' (label 0), the 16 nuScenes-lidarseg classes (1..16), 'free'
    # (17).
    class_names=[
        'others', 'barrier', 'bicycle', 'bus', 'car', 'construction_vehicle',
        'motorcycle', 'pedestrian', 'traffic_cone', 'trailer', 'truck',
        'driveable_surface', 'other_flat', 'sidewalk', 'terrain', 'manmade',
        'vegetation', 'free'
    ],
    empty_class='free',
    labels=[
        dict(type='LoadOccupancyGT', occ_format='occ3d'),
        # Occ3D labels are in the ego frame: move points and cameras there,
        # so the ego frame is the working frame of everything after this
        # step.
        dict(type='PointsToEgoFrame'),
    ],
    metric=dict(
        convention='occ3d',
        # Occ3D's protocol: only voxels seen by a camera count.
        use_camera_mask=True,
        # SDG-OCC Fig. 7 reports IoU by distance from the ego.
        distance_ranges=[(0, 20), (20, 30), (30, 40)]))
