"""Prediction files of format-only runs: names, dtype, shape, content."""
import zipfile

import numpy as np
import pytest
import torch

from projects.occ_common.evaluation import OccupancyMetric
from projects.occ_common.evaluation.occupancy_export import (
    write_occ3d_prediction, write_surroundocc_prediction)
from projects.occ_common.transforms import LoadOccupancyGT

SHAPE = (200, 200, 16)


def _occ3d_grid(seed: int = 0) -> np.ndarray:
    """A scene-like Occ3D grid: free (17) above a driveable ground layer
    (11) with a few random cars (4)."""
    rng = np.random.default_rng(seed)
    grid = np.full(SHAPE, 17, dtype=np.int64)
    grid[:, :, 0] = 11
    cars = rng.integers(0, 200, size=(40, 2))
    for x, y in cars:
        grid[x:x + 4, y:y + 2, 1:3] = 4
    return grid


def test_occ3d_file_layout(tmp_path):
    """<token>.npz with uint8 (200, 200, 16) 'semantics' and the same grid
    as the challenge example's unnamed 'arr_0' and as the 'pred' SparseOcc's
    RayIoU script reads; small (compressed)."""
    pred = _occ3d_grid()
    path = write_occ3d_prediction(str(tmp_path), 'abc123', torch.from_numpy(
        pred))
    assert path == str(tmp_path / 'abc123.npz')
    with np.load(path, allow_pickle=False) as data:
        assert sorted(data.files) == ['arr_0', 'pred', 'semantics']
        for key in data.files:
            assert data[key].dtype == np.uint8
            assert data[key].shape == SHAPE
            np.testing.assert_array_equal(data[key], pred)
    # 640,000 voxels: 5.1 MB as int64, 640 kB as raw uint8.
    assert (tmp_path / 'abc123.npz').stat().st_size < 64_000
    with pytest.raises(ValueError, match='cannot name'):
        write_occ3d_prediction(str(tmp_path), '../x', pred)
    with pytest.raises(ValueError, match='do not fit in uint8'):
        write_occ3d_prediction(str(tmp_path), 't', pred + 300)


def test_surroundocc_file_reads_back_as_a_label(tmp_path):
    """Rows x, y, z, label of the non-empty voxels, uint8; LoadOccupancyGT
    reads the file back to the same dense grid.

    Three occupied voxels: (0, 0, 0) car 4, (199, 5, 15) vegetation 16,
    (10, 20, 3) driveable 11 -> 3 rows, sorted by index.
    """
    pred = np.zeros(SHAPE, dtype=np.int64)
    pred[0, 0, 0], pred[199, 5, 15], pred[10, 20, 3] = 4, 16, 11
    path = write_surroundocc_prediction(str(tmp_path), 'n008__LIDAR_TOP__1'
                                        '.pcd.bin', pred)
    assert path.endswith('n008__LIDAR_TOP__1.pcd.bin.npy')
    rows = np.load(path, allow_pickle=False)
    assert rows.dtype == np.uint8
    np.testing.assert_array_equal(
        rows, [[0, 0, 0, 4], [10, 20, 3, 11], [199, 5, 15, 16]])
    loaded = LoadOccupancyGT('surroundocc')(dict(occ_path=path))
    np.testing.assert_array_equal(loaded['gt_occ'], pred)


def _sample(token, pred, **extra):
    return dict(token=token, sample_idx=token, pred_occ=pred,
                lidar_path=f'/data/samples/LIDAR_TOP/{token}.pcd.bin',
                **extra)


def test_format_only_metric_writes_files_and_zip_without_labels(tmp_path):
    """No gt_occ anywhere: two files, the zip of the folder, no scores."""
    prefix = str(tmp_path / 'submission')
    metric = OccupancyMetric(convention='occ3d', format_only=True,
                             submission_prefix=prefix)
    grids = [_occ3d_grid(0), _occ3d_grid(1)]
    metric.process({}, [_sample('tok0', torch.from_numpy(grids[0]))])
    metric.process({}, [_sample('tok1', torch.from_numpy(grids[1]))])
    assert metric.evaluate(2) == {}
    with zipfile.ZipFile(prefix + '.zip') as archive:
        assert sorted(archive.namelist()) == ['submission/tok0.npz',
                                              'submission/tok1.npz']
    with np.load(tmp_path / 'submission' / 'tok1.npz') as data:
        np.testing.assert_array_equal(data['semantics'], grids[1])
    with pytest.raises(ValueError, match='submission_prefix'):
        OccupancyMetric(convention='occ3d', format_only=True)


def test_submission_prefix_also_scores(tmp_path):
    """With a prefix but not format_only the scores are those of a metric
    without one, and the SurroundOcc files are written."""
    gt = np.zeros(SHAPE, dtype=np.int64)
    gt[:10, :10, 0] = 11
    pred = gt.copy()
    pred[:5, :10, 0] = 0  # half of the 100 ground voxels missed
    results = []
    for prefix in (None, str(tmp_path / 'sub')):
        metric = OccupancyMetric(convention='surroundocc',
                                 submission_prefix=prefix)
        metric.process({}, [_sample('a', torch.from_numpy(pred),
                                    gt_occ=torch.from_numpy(gt),
                                    is_rainy=False, is_night=False)])
        results.append(metric.evaluate(1))
    # NaN (absent classes) compares equal in assert_equal.
    np.testing.assert_equal(results[0], results[1])
    # IoU of driveable_surface: 50 / 100.
    assert results[1]['occ/driveable_surface'] == pytest.approx(50.0)
    assert sorted(p.name for p in (tmp_path / 'sub').iterdir()) == [
        'a.pcd.bin.npy']
