"""Key-frame and multi-sweep LiDAR loading (hand-made .bin files)."""
import warnings

import numpy as np
import pytest
from mmdet3d.datasets.transforms import LoadPointsFromMultiSweeps
from mmdet3d.structures import LiDARPoints

import projects.occ_common.transforms  # noqa: F401  (registers)
from projects.occ_common.transforms.loading import LoadLidarSegLabels
from projects.occ_common.transforms.points_loading import (
    LoadOccPointsFromFile, LoadOccPointsFromMultiSweeps, read_points_file)


def _write(path, rows):
    np.asarray(rows, dtype=np.float32).tofile(str(path))
    return str(path)


def _yaw90_sweep(path, timestamp):
    """sensor2lidar = rotation by +90 deg about z, then translation (2, 0, 0).

    Its exact inverse (what converters store as ``lidar2sensor``) has
    rotation R^T = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]] and translation
    -R^T t = -(0, -2, 0) = (0, 2, 0).
    """
    s2l = np.array([[0., -1, 0, 2], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    return dict(
        lidar_points=dict(
            lidar_path=path, lidar2sensor=np.linalg.inv(s2l).tolist()),
        timestamp=timestamp)


def test_read_points_file_shapes_and_errors(tmp_path):
    """3 points x 5 values read back; empty, truncated and missing files.

    A truncated file of 14 float32 (56 bytes) is not a multiple of
    5 * 4 = 20 bytes.
    """
    rows = np.arange(15, dtype=np.float32).reshape(3, 5)
    out = read_points_file(_write(tmp_path / 'a.bin', rows), 5)
    np.testing.assert_array_equal(out, rows)
    assert read_points_file(_write(tmp_path / 'e.bin', []), 5).shape == (0, 5)
    bad = _write(tmp_path / 'cut.bin', np.arange(14))
    with pytest.raises(ValueError, match=r'cut\.bin has 56 bytes.*20'):
        read_points_file(bad, 5)
    with pytest.raises(FileNotFoundError, match=r'nope\.bin'):
        read_points_file(str(tmp_path / 'nope.bin'), 5)


def test_load_key_frame(tmp_path):
    """LoadOccPointsFromFile returns the 5 columns; a truncated key frame
    names its file."""
    rows = [[1, 2, 3, 0.5, 7], [4, 5, 6, 0.25, 8]]
    path = _write(tmp_path / 'key.bin', rows)
    loader = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    out = loader(dict(lidar_points=dict(lidar_path=path)))
    assert isinstance(out['points'], LiDARPoints)
    np.testing.assert_allclose(out['points'].tensor.numpy(), rows)
    cut = _write(tmp_path / 'key_cut.bin', np.arange(7))
    with pytest.raises(ValueError, match='key_cut.bin'):
        loader(dict(lidar_points=dict(lidar_path=cut)))


def test_sweep_is_moved_exactly_and_mmdet3d_is_not(tmp_path):
    """A sweep point p_s = (1, 0, 0) with sensor2lidar = [R | t] (R: +90 deg
    about z, t = (2, 0, 0)) lies at R p_s + t = (0, 1, 0) + (2, 0, 0) =
    (2, 1, 0) in the key frame. mmdet3d 1.4 computes p_s @ R^T - (0, 2, 0) =
    (0, 1, 0) - (0, 2, 0) = (0, -1, 0) (open-mmlab/mmdetection3d#3054).
    The time lag is 10.0 - 9.95 = 0.05 s; key-frame column 4 becomes 0.
    """
    key = _write(tmp_path / 'key.bin', [[5, 5, 1, 0.3, 9]])
    sweep = _write(tmp_path / 'sweep.bin', [[1, 0, 0, 0.7, 3]])
    results = dict(
        timestamp=10.0,
        token='tok',
        lidar_points=dict(lidar_path=key),
        lidar_sweeps=[_yaw90_sweep(sweep, 9.95)],
        pts_semantic_mask=np.array([4]))
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    ours = LoadOccPointsFromMultiSweeps(sweeps_num=10)(load(dict(results)))
    np.testing.assert_allclose(
        ours['points'].tensor.numpy(),
        [[5, 5, 1, 0.3, 0], [2, 1, 0, 0.7, 0.05]],
        atol=1e-6)
    np.testing.assert_array_equal(ours['pts_semantic_mask'], [4, 255])
    theirs = LoadPointsFromMultiSweeps(sweeps_num=10, use_dim=[0, 1, 2])(
        load(dict(results)))
    np.testing.assert_allclose(
        theirs['points'].tensor.numpy()[1], [0, -1, 0], atol=1e-6)


def test_sweep_errors_name_the_file(tmp_path):
    """A missing and a truncated sweep both raise with the sweep's path."""
    key = _write(tmp_path / 'key.bin', [[0, 0, 0, 0, 0]])
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    merge = LoadOccPointsFromMultiSweeps()
    for name, exc in (('gone.bin', FileNotFoundError), ('cut.bin',
                                                        ValueError)):
        if name == 'cut.bin':
            _write(tmp_path / name, np.arange(6))
        results = load(
            dict(
                timestamp=1.0,
                token='tok',
                lidar_points=dict(lidar_path=key),
                lidar_sweeps=[_yaw90_sweep(str(tmp_path / name), 0.9)]))
        with pytest.raises(exc, match=f'sample tok.*{name}'):
            merge(results)


def test_empty_key_frame_and_sweep(tmp_path):
    """Zero points in the key frame and in the sweep give (0, 5) points and
    an empty label array, not an error."""
    key = _write(tmp_path / 'key.bin', [])
    sweep = _write(tmp_path / 'sweep.bin', [])
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    results = load(
        dict(
            timestamp=1.0,
            lidar_points=dict(lidar_path=key),
            lidar_sweeps=[_yaw90_sweep(sweep, 0.95)],
            pts_semantic_mask=np.zeros(0, np.int64)))
    out = LoadOccPointsFromMultiSweeps()(results)
    assert out['points'].tensor.shape == (0, 5)
    assert out['pts_semantic_mask'].shape == (0, )
    assert 'sweeps_num=10' in repr(LoadOccPointsFromMultiSweeps())


#: Two nuScenes-like points: x, y, z, intensity, ring.
NUSCENES_ROWS = [[12.345, -3.21, 0.875, 17, 3], [-40.5, 7.125, -1.6, 2, 31]]


@pytest.mark.parametrize('layout', ['float64', '4 values a point'])
def test_file_of_another_dtype_or_width_is_refused(tmp_path, layout):
    """Both files have the size of whole 5 x float32 points (2 x 5 x 8 =
    80 bytes; 5 x 4 x 4 = 80 bytes), so the size check passes; read as
    float32 x 5, their fifth values are no ring indices (e.g. the high
    word of -1.6 in float64). Before, they loaded as garbage points."""
    path = str(tmp_path / 'key.bin')
    if layout == 'float64':
        np.asarray(NUSCENES_ROWS, np.float64).tofile(path)
    else:
        np.asarray(NUSCENES_ROWS * 3, np.float32)[:5, :4].tofile(path)
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    with pytest.raises(ValueError, match=r'key\.bin: the fifth value .* '
                       r'no ring index .* another dtype'):
        load(dict(lidar_points=dict(lidar_path=path)))
    unchecked = LoadOccPointsFromFile(
        coord_type='LIDAR', load_dim=5, use_dim=5, check_ring=False)
    assert len(unchecked(dict(lidar_points=dict(lidar_path=path)))[
        'points']) == 4


def test_load_dim_must_match_the_recorded_point_width(tmp_path):
    """The info records num_pts_feats=4: load_dim=5 is refused, naming
    the info file, the sample and the LiDAR file."""
    path = _write(tmp_path / 'key.bin', NUSCENES_ROWS)
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    with pytest.raises(ValueError, match=r'infos\.pkl: sample tok records 4 '
                       r'values .* load_dim is 5: .*key\.bin'):
        load(dict(lidar_points=dict(lidar_path=path), num_pts_feats=4,
                  token='tok', ann_file='infos.pkl'))


def test_nan_points_are_dropped_with_one_warning_per_file(tmp_path):
    """Key frame: 1 of 3 points NaN, dropped with its lidarseg label (the
    labels stay aligned); a sweep all NaN: dropped, 'all 2 points' said
    once, however often the file is read."""
    rows = NUSCENES_ROWS + [[np.nan, 0, 0, 1, 2]]
    key = _write(tmp_path / 'key.bin', rows)
    labels = tmp_path / 'labels.bin'
    # Raw car, driveable, vegetation -> 4, 11, 16; the NaN point's goes.
    np.array([17, 24, 30], np.uint8).tofile(labels)
    sweep = _write(tmp_path / 'sweep.bin', np.full((2, 5), np.nan))
    results = dict(
        timestamp=1.0, token='tok', lidar_points=dict(lidar_path=key),
        lidar_sweeps=[_yaw90_sweep(sweep, 0.9)],
        pts_semantic_mask_path=str(labels))
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    with pytest.warns(UserWarning, match=r'key\.bin: 1 of 3 points have '
                      'NaN / inf values and are dropped'):
        out = LoadLidarSegLabels()(load(dict(results)))
    np.testing.assert_allclose(out['points'].tensor.numpy(), NUSCENES_ROWS,
                               rtol=1e-6)
    np.testing.assert_array_equal(out['pts_semantic_mask'], [4, 11])
    merge = LoadOccPointsFromMultiSweeps()
    with pytest.warns(UserWarning, match=r'sweep of sample tok file .*'
                      r'sweep\.bin: all 2 points have NaN'):
        merged = merge(out)
    assert len(merged['points']) == 2
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        merge(LoadLidarSegLabels()(load(dict(results))))


def test_string_timestamp_names_the_sample_and_sweep(tmp_path):
    """A sweep timestamp read as a string (before: TypeError "unsupported
    operand type(s) for -: 'float' and 'str'", naming nothing)."""
    key = _write(tmp_path / 'key.bin', NUSCENES_ROWS)
    sweep = _write(tmp_path / 'sweep.bin', NUSCENES_ROWS)
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    results = load(dict(timestamp=1.0, token='tok',
                        lidar_points=dict(lidar_path=key),
                        lidar_sweeps=[_yaw90_sweep(sweep, '0.95')]))
    with pytest.raises(ValueError, match=r'sample tok: timestamp of sweep '
                       r'.*sweep\.bin must be a number of seconds, got str'):
        LoadOccPointsFromMultiSweeps()(results)
