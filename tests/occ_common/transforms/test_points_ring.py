"""LoadOccPointsFromMultiSweeps(record_ring=True) keeps every merged
point's ring index beside the time lag that replaces it."""
import numpy as np
from mmdet3d.structures.points import LiDARPoints

from projects.occ_common.transforms import LoadOccPointsFromMultiSweeps


def test_rings_of_key_frame_and_sweeps(tmp_path):
    """Key frame rings 3, 7; one sweep of rings 0, 31 at 0.05 s: the merged
    cloud's rings are 3, 7, 0, 31 in its row order, as int16."""
    sweep = np.array([[5, 0, 0, 1, 0], [6, 0, 0, 1, 31]], np.float32)
    path = str(tmp_path / 'sweep.bin')
    sweep.tofile(path)
    key = np.array([[1, 0, 0, 1, 3], [2, 0, 0, 1, 7]], np.float32)
    results = dict(points=LiDARPoints(key.copy(), points_dim=5),
                   timestamp=1.0,
                   lidar_sweeps=[dict(lidar_points=dict(
                       lidar_path=path, sensor2lidar=np.eye(4)),
                       timestamp=0.95)])
    out = LoadOccPointsFromMultiSweeps(
        sweeps_num=1, test_mode=True, record_ring=True)(results)
    np.testing.assert_array_equal(out['points_ring'], [3, 7, 0, 31])
    assert out['points_ring'].dtype == np.int16
    np.testing.assert_allclose(out['points'].tensor[:, 4],
                               [0, 0, 0.05, 0.05], atol=1e-6)


def test_off_by_default():
    key = np.array([[1, 0, 0, 1, 3]], np.float32)
    out = LoadOccPointsFromMultiSweeps(sweeps_num=1, test_mode=True)(
        dict(points=LiDARPoints(key, points_dim=5), timestamp=1.0,
             lidar_sweeps=None))
    assert 'points_ring' not in out
