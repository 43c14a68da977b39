"""Reading back the files of tools/test.py --format-only."""
import numpy as np
import pytest

from projects.occ_common.evaluation.occupancy_export import write_prediction
from projects.occ_common.evaluation.prediction_files import (prediction_path,
                                                             read_prediction)

SAMPLE = dict(sample_idx=3, token='tok3',
              lidar_path='/data/samples/LIDAR_TOP/n015__LIDAR_TOP__1.pcd.bin')


def _grid(empty: int) -> np.ndarray:
    grid = np.full((4, 3, 2), empty, dtype=np.uint8)
    grid[0, 0, 0] = 11
    grid[3, 2, 1] = 4
    return grid


@pytest.mark.parametrize('convention,empty', [('occ3d', 17),
                                              ('surroundocc', 0)])
def test_written_files_read_back(convention, empty, tmp_path):
    """Each layout round-trips: the path found for the sample is the file
    write_prediction wrote (Occ3D by token, SurroundOcc by LiDAR file
    name), and the grid read is the one written."""
    grid = _grid(empty)
    name = write_prediction(str(tmp_path), convention, SAMPLE, grid, empty)
    path = prediction_path(str(tmp_path), convention, SAMPLE)
    assert path == str(tmp_path / name)
    np.testing.assert_array_equal(read_prediction(path, grid.shape, empty),
                                  grid)


def test_bad_files_name_themselves(tmp_path):
    missing = str(tmp_path / 'tok3.npz')
    with pytest.raises(FileNotFoundError, match='tok3.npz'):
        read_prediction(missing, (4, 3, 2), 17)
    np.savez(tmp_path / 'other.npz', logits=np.zeros((4, 3, 2)))
    with pytest.raises(ValueError, match=r"other.npz: expected one of"):
        read_prediction(str(tmp_path / 'other.npz'), (4, 3, 2), 17)
    np.savez(tmp_path / 'small.npz', semantics=np.zeros((2, 3, 2)))
    with pytest.raises(ValueError, match=r'shape \(2, 3, 2\), expected'):
        read_prediction(str(tmp_path / 'small.npz'), (4, 3, 2), 17)
    np.save(tmp_path / 'rows.npy', np.array([[9, 0, 0, 4]], np.uint8))
    with pytest.raises(ValueError, match=r'voxel \[9, 0, 0\] is outside'):
        read_prediction(str(tmp_path / 'rows.npy'), (4, 3, 2), 0)
    with pytest.raises(ValueError, match="has no 'token'"):
        prediction_path(str(tmp_path), 'occ3d', dict(sample_idx=1))
    with pytest.raises(ValueError, match=r"sample token '\.\./x' cannot name a file"):
        prediction_path(str(tmp_path), 'occ3d', dict(token='../x'))
