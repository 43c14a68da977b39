"""The ego vehicle's own returns leave the key frame and every sweep."""
import os.path as osp

import numpy as np
import pytest
from mmdet3d.structures import LiDARPoints

from projects.occ_common.fileio.safe_pickle import load_info_file
from projects.occ_common.transforms.ego_points import (NUSCENES_EGO_BOX,
                                                       RemoveEgoPoints,
                                                       in_ego_box)
from projects.occ_common.transforms.points_loading import \
    LoadOccPointsFromMultiSweeps

REAL = osp.join(
    osp.dirname(osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))),
    '..', 'shared', 'data', 'nuscenes_real_sample')
REAL_INFO = osp.join(REAL, 'n015-2018-07-24-11-22-45+0800.pkl')

#: nuScenes' LIDAR_TOP mount: yaw -90 deg, (0.985, 0, 1.84) m. The
#: rotation maps sensor (x, y) to ego (y, -x).
LIDAR2EGO = np.array([[0., 1, 0, 0.985], [-1, 0, 0, 0], [0, 0, 1, 1.84],
                      [0, 0, 0, 1]])

#: Sensor-frame points, their ego coordinates and whether they are inside
#: NUSCENES_EGO_BOX (-0.9, -1.1, -0.5, 3.7, 1.1, 2.2).
CASES = [
    ((0, 0, 0), (0.985, 0, 1.84), True),  # the sensor itself
    ((0, 2.5, -0.9), (3.485, 0, 0.94), True),  # the bonnet
    ((0, 3.0, -0.9), (3.985, 0, 0.94), False),  # x > 3.7: ahead of it
    ((-1.2, 0, 0), (0.985, 1.2, 1.84), False),  # y > 1.1 (r = 1.2 m!)
    ((1.05, 0.5, -1.0), (1.485, -1.05, 0.84), True),  # right mirror
    ((0, -1.9, 0.3), (-0.915, 0, 2.14), False),  # x < -0.9: behind it
    ((0, 0, 0.5), (0.985, 0, 2.34), False),  # z > 2.2: above the sensor
]


def _key_frame():
    """The seven points with intensity 10 + i and ring index 20 + i."""
    xyz = np.array([c[0] for c in CASES], dtype=np.float32)
    extra = np.stack([10 + np.arange(7), 20 + np.arange(7)], 1)
    return np.concatenate([xyz, extra.astype(np.float32)], 1)


def test_box_membership_by_hand():
    """The ego coordinates of the docstring table, and who is inside."""
    xyz = _key_frame()[:, :3]
    ego = xyz @ LIDAR2EGO[:3, :3].T + LIDAR2EGO[:3, 3]
    np.testing.assert_allclose(ego, [c[1] for c in CASES], atol=1e-6)
    np.testing.assert_array_equal(
        in_ego_box(xyz, LIDAR2EGO, NUSCENES_EGO_BOX), [c[2] for c in CASES])


def test_remove_ego_points_keeps_every_column_and_label():
    """Points 0, 1 and 4 go (num_ego_points = 3); the four others keep
    their x, y, z, intensity and ring index; the lidarseg labels (100 +
    i) go with their points."""
    rows = _key_frame()
    out = RemoveEgoPoints()(
        dict(points=LiDARPoints(rows.copy(), points_dim=5),
             lidar2ego=LIDAR2EGO,
             pts_semantic_mask=100 + np.arange(7)))
    kept = [2, 3, 5, 6]
    np.testing.assert_array_equal(out['points'].tensor.numpy(), rows[kept])
    np.testing.assert_array_equal(out['pts_semantic_mask'],
                                  100 + np.array(kept))
    assert out['num_ego_points'] == 3
    # No point: nothing to remove.
    empty = RemoveEgoPoints()(dict(points=np.zeros((0, 5), np.float32),
                                   lidar2ego=LIDAR2EGO))
    assert empty['points'].shape == (0, 5) and empty['num_ego_points'] == 0


def test_remove_ego_points_refuses_what_it_cannot_do():
    """A malformed box, labels of another length, and points that are no
    longer in the sensor frame are errors."""
    with pytest.raises(ValueError, match='x0 < x1'):
        RemoveEgoPoints(ego_box=(1, 0, 0, 0, 1, 1))
    state = dict(points=_key_frame(), lidar2ego=LIDAR2EGO)
    with pytest.raises(ValueError,
                       match='6 labels but .* 7 points; load the labels'):
        RemoveEgoPoints()(dict(state, pts_semantic_mask=np.zeros(6)))
    with pytest.raises(ValueError, match='sensor frame'):
        RemoveEgoPoints()(dict(state, points_time_dim=4))


def test_sweeps_lose_the_ego_in_their_own_frame(tmp_path):
    """A sweep holding the sensor point, the bonnet point and the point
    ahead of the car (CASES 0-2, in the sweep's own frame): only the last
    survives, and is then moved to the key frame by sensor2lidar, a
    shift of 5 m along x: (0, 3, -0.9) -> (5, 3, -0.9), time lag 0.1 s.
    Without ego_box all three arrive."""
    path = str(tmp_path / 'sweep.bin')
    _key_frame()[:3].tofile(path)
    shift = np.eye(4)
    shift[0, 3] = 5.0
    sweep = dict(
        lidar_points=dict(lidar_path=path, sensor2lidar=shift,
                          lidar2ego=LIDAR2EGO),
        timestamp=0.9)

    def merge(**kwargs):
        key = LiDARPoints(np.zeros((0, 5), np.float32), points_dim=5)
        loader = LoadOccPointsFromMultiSweeps(sweeps_num=1, **kwargs)
        state = dict(points=key, timestamp=1.0, lidar_sweeps=[sweep])
        return loader(state)['points'].tensor.numpy()

    out = merge(ego_box=NUSCENES_EGO_BOX)
    np.testing.assert_allclose(out, [[5.0, 3.0, -0.9, 12.0, 0.1]],
                               atol=1e-6)
    assert len(merge()) == 3


@pytest.mark.skipif(not osp.isfile(REAL_INFO),
                    reason='the real nuScenes sample (../shared) is absent')
def test_real_key_frame_loses_its_car():
    """The real key frame: 8,526 of its 34,688 points are the car (24.6 %),
    among them all 8,396 within 1.3 m of the sensor and 130 on the bonnet
    (up to 2.1 m away); the nearest point kept is 3.5 m away, so no point
    of the scene goes. Kept rows are the file's rows, all five columns."""
    info = load_info_file(REAL_INFO)['data_list'][0]
    raw = np.fromfile(
        osp.join(REAL, info['lidar_points']['lidar_path']),
        np.float32).reshape(-1, 5)
    out = RemoveEgoPoints()(
        dict(points=LiDARPoints(raw.copy(), points_dim=5),
             lidar2ego=np.asarray(info['lidar_points']['lidar2ego'])))
    kept = out['points'].tensor.numpy()
    assert len(raw) == 34688
    assert out['num_ego_points'] == 8526 == len(raw) - len(kept)
    dist = np.linalg.norm(raw[:, :3], axis=1)
    removed = ~np.isin(np.arange(len(raw)), _row_index(raw, kept))
    assert removed.sum() == 8526
    assert (dist < 1.3).sum() == 8396 and removed[dist < 1.3].all()
    assert dist[removed].max() < 2.1
    assert np.linalg.norm(kept[:, :3], axis=1).min() > 3.5
    np.testing.assert_array_equal(kept, raw[~removed])


def _row_index(raw: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """Indices of ``kept``'s rows in ``raw`` (rows are unique there)."""
    lookup = {row.tobytes(): i for i, row in enumerate(raw)}
    return np.array([lookup[row.tobytes()] for row in kept])
