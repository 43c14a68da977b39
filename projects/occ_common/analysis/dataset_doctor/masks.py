"""Visibility masks: how much they cover, and whether they fit the sensors.

Occ3D's labels carry two masks: ``mask_lidar`` (voxels the LiDAR's rays
reached) and ``mask_camera`` (voxels some camera sees); the camera-only
protocol trains and scores inside ``mask_camera``. Numbers:

* ``camera_coverage`` / ``lidar_coverage``: share of the grid in the mask;
* ``occupied_in_camera`` / ``occupied_in_lidar``: share of the occupied
  voxels in the mask;
* ``points_in_lidar_mask``: share of the key frame's points (in the grid)
  whose voxel, or the one half a voxel further along the ray, is in
  ``mask_lidar`` (a mask of another frame, flipped or shifted, misses
  them);
* ``camera_mask_in_view``: share of the ``mask_camera`` voxels whose
  centre projects into some camera's image (a mask made for another rig,
  or in another frame, lies partly where no camera looks).

SurroundOcc's labels have no masks: the check is skipped for them.
"""
import numpy as np

from ...visualization.camera_overlay import voxel_centres
from .grid import LabelGrid
from .labels_lidar import configured_reading, grid_points
from .sample_data import SampleData
from .verdict import CheckResult

#: ``points_in_lidar_mask`` below these: fail, warn. The synthetic world
#: measures 1.00 (its mask is traced from the same rays).
FAIL_POINTS, WARN_POINTS = 0.5, 0.8
#: ``camera_mask_in_view`` below these: fail, warn.
FAIL_IN_VIEW, WARN_IN_VIEW = 0.5, 0.9


def in_some_view(centres: np.ndarray, sample: SampleData,
                 grid2lidar: np.ndarray) -> np.ndarray:
    """Which grid-frame points project into some camera's image.

    Args:
        centres (np.ndarray): Shape (M, 3), the grid's frame.
        sample (SampleData): Its cameras (the image size: the image's, or
            the recorded one).
        grid2lidar (np.ndarray): Shape (4, 4).

    Returns:
        np.ndarray: bool. Shape (M,).
    """
    seen = np.zeros(len(centres), bool)
    for camera in sample.cameras:
        size = camera.image.shape[:2] if camera.image is not None \
            else camera.recorded_size
        if size is None:
            continue
        mat = camera.lidar2img @ grid2lidar
        cam = centres @ mat[:3, :3].T + mat[:3, 3]
        front = cam[:, 2] > 0.1
        u = cam[front, 0] / cam[front, 2]
        v = cam[front, 1] / cam[front, 2]
        hit = np.zeros(len(centres), bool)
        hit[front] = (u >= 0) & (u < size[1]) & (v >= 0) & (v < size[0])
        seen |= hit
    return seen


def check_masks(sample: SampleData, grid: LabelGrid) -> CheckResult:
    """The ``masks`` check of one sample (see the module doc).

    Args:
        sample (SampleData): The sample.
        grid (LabelGrid): The config's grid.

    Returns:
        CheckResult: The numbers of the module doc.
    """
    result = CheckResult('masks')
    if sample.labels is None:
        result.skipped = 'no occupancy labels'
        return result
    if sample.mask_camera is None or sample.mask_lidar is None:
        result.skipped = f'{grid.occ_format} labels have no visibility masks'
        return result
    occupied = grid.occupied(sample.labels)
    for name, mask in (('camera', sample.mask_camera),
                       ('lidar', sample.mask_lidar)):
        coverage = float(mask.mean())
        result.numbers[f'{name}_coverage'] = coverage
        result.numbers[f'occupied_in_{name}'] = float(
            mask[occupied].mean()) if occupied.any() else float('nan')
        if coverage == 0:
            result.fail(f'mask_{name} is empty: no voxel would be trained')
        elif coverage == 1:
            result.warn(f'mask_{name} marks every voxel (no mask?)')
    xyz, origin = grid_points(sample, grid)
    reading = configured_reading(xyz, origin, grid)
    if reading.inside.any():
        share = float(reading.on(sample.mask_lidar)[reading.inside].mean())
        result.numbers['points_in_lidar_mask'] = share
        result.judge(share, '{value:.2f} of the key frame\'s points lie in '
                     'mask_lidar (a mask of another frame, flipped or '
                     'shifted?)', lambda v: v < FAIL_POINTS,
                     lambda v: v < WARN_POINTS)
    index = np.argwhere(sample.mask_camera)
    if len(index) and sample.cameras:
        centres = voxel_centres(index, grid.pc_range, grid.voxel_size)
        grid2lidar = np.linalg.inv(grid.lidar2grid(sample.lidar2ego))
        share = float(in_some_view(centres, sample, grid2lidar).mean())
        result.numbers['camera_mask_in_view'] = share
        result.judge(share, '{value:.2f} of the mask_camera voxels lie in '
                     'some camera\'s view (a mask of another rig or frame?)',
                     lambda v: v < FAIL_IN_VIEW, lambda v: v < WARN_IN_VIEW)
    return result
