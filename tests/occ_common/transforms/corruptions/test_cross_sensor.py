"""The late LiDAR and the told extrinsics, on numbers by hand."""
import numpy as np
import pytest
from mmdet3d.structures.points import LiDARPoints

from projects.occ_common.transforms.corruptions import OccCorruption
from projects.occ_common.transforms.corruptions.lidar import points_array


def _shift_x(metres):
    """A 4x4 translation along x."""
    mat = np.eye(4)
    mat[0, 3] = metres
    return mat


def _late(delay_severity, **extra):
    """One point at (5, 0, 0); sweeps 1 m and 2 m behind the key frame's
    sensor (sweep -> key = +x shifts of -1 and -2), 50 and 100 ms old,
    listed oldest first."""
    sweeps = [
        dict(timestamp=9.90, lidar_points=dict(sensor2lidar=_shift_x(-2))),
        dict(timestamp=9.95, lidar_points=dict(sensor2lidar=_shift_x(-1))),
    ]
    results = dict(token='t', timestamp=10.0, lidar_sweeps=sweeps,
                   points=LiDARPoints(np.array([[5., 0, 0, 1, 0]],
                                               np.float32), points_dim=5),
                   **extra)
    return OccCorruption('temporal_misalignment', delay_severity)(results)


def test_late_lidar_sees_from_the_old_pose():
    """Severity 1 (2 sweeps) asks for the second newest sweep, 100 ms old,
    its sensor 2 m behind: the point lies 2 m further ahead of it, at
    (7, 0, 0). Severity 2 (4 sweeps) falls back to the oldest, the same."""
    out = _late(1)
    np.testing.assert_allclose(points_array(out)[0, :3], [7, 0, 0])
    assert out['corruption_delay_s'] == pytest.approx(0.1)
    assert _late(2)['corruption_delay_s'] == pytest.approx(0.1)


def test_late_lidar_in_the_ego_frame():
    """Once the points are in the ego frame (sensor turned 90 degrees about
    z and 2 m up), the late offset turns with it: (5, 0, 0) of the ego is
    (0, -5, -2) of the sensor, late (2, -5, -2), and back in the ego frame
    (5, 2, 0): the sensor's +x is the ego's +y."""
    lidar2ego = np.array([[0., -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 2],
                          [0, 0, 0, 1]])
    out = _late(1, ori_lidar2ego=lidar2ego)
    np.testing.assert_allclose(points_array(out)[0, :3], [5, 2, 0],
                               atol=1e-6)


def test_no_sweeps_no_late_data():
    results = dict(token='t', timestamp=1.0, lidar_sweeps=[],
                   points=LiDARPoints(np.ones((3, 5), np.float32),
                                      points_dim=5))
    out = OccCorruption('temporal_misalignment', 5)(results)
    assert out['corruption_delay_s'] == 0.0
    np.testing.assert_array_equal(points_array(out), np.ones((3, 5)))
