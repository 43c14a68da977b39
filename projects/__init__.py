"""OpenMMLab mmdet3d plugins for multi-modal 3D semantic occupancy."""
