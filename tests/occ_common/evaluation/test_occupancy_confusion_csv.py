"""Tests of the confusion-matrix CSV files and their reading."""
import numpy as np
import pytest

from projects.occ_common.evaluation import (largest_confusions,
                                            read_confusion_csv,
                                            write_confusion_csv)


def test_round_trip_and_layout(tmp_path):
    """A 3-class matrix: header of names, one named row of counts per GT."""
    path = tmp_path / 'c.csv'
    confusion = np.array([[5, 0, 1], [2, 3, 0], [0, 0, 7]])
    write_confusion_csv(str(path), confusion, ('empty', 'car', 'road'))
    assert path.read_text().splitlines() == [
        'gt \\ pred,empty,car,road', 'empty,5,0,1', 'car,2,3,0', 'road,0,0,7'
    ]
    names, counts = read_confusion_csv(str(path))
    assert names == ['empty', 'car', 'road']
    assert counts.dtype == np.int64
    assert np.array_equal(counts, confusion)


def test_wrong_shape_names_the_file(tmp_path):
    with pytest.raises(ValueError, match=r'c\.csv.*\(2, 2\).*\(3, 3\)'):
        write_confusion_csv(str(tmp_path / 'c.csv'), np.zeros((3, 3)),
                            ('a', 'b'))


@pytest.mark.parametrize('text, message', [
    ('a,b\n', 'header row'),
    ('gt \\ pred,a,b\nb,1,2\na,3,4\n', 'one row per class'),
    ('gt \\ pred,a,b\na,1,2\nb,3\n', 'one row per class'),
    ('gt \\ pred,a,b\na,1,2\nb,3,x\n', 'not an integer'),
])
def test_bad_files_are_refused(tmp_path, text, message):
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    with pytest.raises(ValueError, match=f'bad.csv.*{message}'):
        read_confusion_csv(str(path))


def test_largest_confusions():
    """Row 1 = (2, 3, 0, 5, 0): of its 10 voxels, class 3 takes 50 %,
    class 0 20 %; class 2 and 4 take none; the diagonal is not a
    confusion. Ties go to the lower label; an empty row gives nothing."""
    confusion = np.array([[1, 0, 0, 0, 0], [2, 3, 0, 5, 0], [1, 0, 0, 1, 0],
                          [0, 0, 0, 0, 0], [0, 0, 0, 0, 0]])
    assert largest_confusions(confusion, 1) == [(3, 0.5), (0, 0.2)]
    assert largest_confusions(confusion, 1, k=4) == [(3, 0.5), (0, 0.2)]
    assert largest_confusions(confusion, 2, k=1) == [(0, 0.5)]
    assert largest_confusions(confusion, 3) == []
