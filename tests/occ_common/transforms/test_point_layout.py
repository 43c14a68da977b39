"""The LiDAR point layout comes from the info file: nuScenes' x, y, z,
intensity, ring and a LiDAR's x, y, z, intensity go through one pipeline
(hand-made .bin files)."""
import numpy as np
import pytest

import projects.occ_common.transforms  # noqa: F401  (registers)
from projects.occ_common.transforms.points_loading import (
    LoadOccPointsFromFile, LoadOccPointsFromMultiSweeps, with_time_lag)

#: Two points: x, y, z, intensity (and ring 7 / 8 in the 5-value files).
ROWS = np.array([[1, 2, 3, 0.5], [4, 5, 6, 0.25]], np.float32)


def _write(path, rows) -> str:
    np.asarray(rows, np.float32).tofile(str(path))
    return str(path)


def _sample(path, num_pts_feats, sweeps=None):
    return dict(lidar_points=dict(lidar_path=path),
                num_pts_feats=num_pts_feats, token='t', timestamp=10.0,
                lidar_sweeps=sweeps)


def test_key_frame_reads_the_recorded_layout(tmp_path):
    """load_dim=None: a 5-value file (ring 7, 8) and a 4-value one give the
    same x, y, z, intensity with use_dim=4; the recorded count is needed;
    use_dim beyond it is refused naming the sample."""
    ring = _write(tmp_path / 'ring.bin', np.c_[ROWS, [7, 8]])
    plain = _write(tmp_path / 'plain.bin', ROWS)
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=None,
                                 use_dim=4)
    for path, dims in ((ring, 5), (plain, 4)):
        out = load(_sample(path, dims))
        np.testing.assert_array_equal(out['points'].tensor.numpy(), ROWS)
    assert load.load_dim is None  # per sample, not remembered
    with pytest.raises(ValueError, match='records no num_pts_feats'):
        load(dict(lidar_points=dict(lidar_path=plain), token='t'))
    wide = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=None,
                                 use_dim=5)
    with pytest.raises(ValueError, match=r'sample t has 4 values'):
        wide(_sample(plain, 4))


def test_time_lag_is_appended_or_written(tmp_path):
    """x, y, z, intensity gain a fifth column (the lag); a fifth value
    (ring) is replaced by it."""
    np.testing.assert_array_equal(with_time_lag(ROWS.copy(), 0.5),
                                  np.c_[ROWS, [0.5, 0.5]])
    ringed = np.c_[ROWS, [7, 8]].astype(np.float32)
    np.testing.assert_array_equal(with_time_lag(ringed, 0.0),
                                  np.c_[ROWS, [0, 0]])


def test_sweeps_of_a_lidar_without_ring_index(tmp_path):
    """A 4-value key frame and a 4-value sweep 0.05 s older, identity
    sensor2lidar: 4 merged points of x, y, z, intensity, lag (0 for the
    key frame, 0.05 for the sweep), exactly as from 5-value files."""
    merged = {}
    for dims, rows in ((4, ROWS), (5, np.c_[ROWS, [7, 8]])):
        key = _write(tmp_path / f'key{dims}.bin', rows)
        sweep = _write(tmp_path / f'sweep{dims}.bin', rows)
        sweeps = [dict(lidar_points=dict(lidar_path=sweep,
                                         sensor2lidar=np.eye(4)),
                       timestamp=9.95)]
        state = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=None,
                                      use_dim=4)(_sample(key, dims, sweeps))
        merged[dims] = LoadOccPointsFromMultiSweeps(
            load_dim=None, test_mode=True)(state)['points'].tensor.numpy()
    np.testing.assert_allclose(
        merged[4], np.r_[np.c_[ROWS, [0, 0]], np.c_[ROWS, [0.05, 0.05]]],
        atol=1e-6)
    np.testing.assert_array_equal(merged[4], merged[5])
    with pytest.raises(ValueError, match='load_dim >= 4'):
        LoadOccPointsFromMultiSweeps(load_dim=3)


def test_rings_are_kept_where_the_files_have_them(tmp_path):
    """keep_rings (the pipeline of a corruption that drops beams): the
    key-frame loader keeps column 4 and the sweeps loader records the
    rings of 5-value files (7, 8 for the key frame and the sweep alike,
    the lag in column 4); a LiDAR without ring index is refused, naming
    the sample."""
    from projects.occ_common.transforms.corruptions.pipeline import keep_rings
    pipeline = [dict(type='LoadOccPointsFromFile', coord_type='LIDAR',
                     load_dim=None, use_dim=4),
                dict(type='LoadOccPointsFromMultiSweeps', load_dim=None,
                     test_mode=True)]
    keep_rings(pipeline)
    assert pipeline[0]['use_dim'] == 5 and pipeline[1]['record_ring']
    key_load, sweep_load = (
        cls(**{k: v for k, v in t.items() if k != 'type'})
        for cls, t in zip((LoadOccPointsFromFile,
                           LoadOccPointsFromMultiSweeps), pipeline))
    for dims, rows in ((5, np.c_[ROWS, [7, 8]]), (4, ROWS)):
        key = _write(tmp_path / f'key{dims}.bin', rows)
        sweeps = [dict(lidar_points=dict(
            lidar_path=_write(tmp_path / f'sweep{dims}.bin', rows),
            sensor2lidar=np.eye(4)), timestamp=9.95)]
        if dims == 4:
            with pytest.raises(ValueError, match=r'sample t has 4 values'):
                key_load(_sample(key, dims, sweeps))
            continue
        out = sweep_load(key_load(_sample(key, dims, sweeps)))
        np.testing.assert_array_equal(out['points_ring'], [7, 8, 7, 8])
        np.testing.assert_allclose(out['points'].tensor.numpy()[:, 4],
                                   [0, 0, 0.05, 0.05], atol=1e-6)
