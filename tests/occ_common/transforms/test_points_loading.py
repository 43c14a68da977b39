"""Key-frame and multi-sweep LiDAR loading (hand-made .bin files)."""
import numpy as np
import pytest
from mmdet3d.datasets.transforms import LoadPointsFromMultiSweeps
from mmdet3d.structures import LiDARPoints

import projects.occ_common.transforms  # noqa: F401  (registers)
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
