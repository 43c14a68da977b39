"""Visualisation of the occupancy plugins: pictures of occupancy grids.

Pure numpy / Pillow / matplotlib (Agg) renderers, no display needed:
:func:`render_bev` (top-down), :func:`render_voxels` (3D perspective),
:func:`occupancy_errors` (error map), :func:`overlay_on_cameras` and the
composed picture :func:`render_occ_figure` / :func:`render_data_sample`;
:class:`OccLocalVisualizer` is the configs' ``visualizer`` (mmdet3d's
``browse_dataset`` draws through it).
The hook that draws them during testing is
:class:`~projects.occ_common.engine.hooks.OccVisualizationHook`.
"""
from .bev_view import render_bev, top_labels
from .camera_overlay import overlay_on_cameras
from .error_map import error_counts, occupancy_errors
from .label_grid import as_label_grid, occupied_voxels
from .occ_figure import render_occ_figure, save_png
from .occ_visualizer import OccLocalVisualizer
from .orientation import (CONVENTION_FORWARD, FORWARD_HEADINGS,
                          forward_from_lidar2ego, sample_forward)
from .palette import (CONVENTIONS, ERROR_NAMES, ERROR_PALETTE, class_palette,
                      convention_classes, resolve_palette)
from .sample_figure import (camera_images, render_data_sample, sample_field,
                            sample_name)
from .voxel_view import render_voxels

__all__ = [
    'CONVENTIONS', 'CONVENTION_FORWARD', 'ERROR_NAMES', 'ERROR_PALETTE',
    'FORWARD_HEADINGS', 'OccLocalVisualizer', 'as_label_grid',
    'camera_images', 'class_palette', 'convention_classes', 'error_counts',
    'forward_from_lidar2ego',
    'occupancy_errors', 'occupied_voxels', 'overlay_on_cameras',
    'render_bev', 'render_data_sample', 'render_occ_figure',
    'render_voxels', 'resolve_palette', 'sample_field', 'sample_forward',
    'sample_name', 'save_png', 'top_labels'
]
