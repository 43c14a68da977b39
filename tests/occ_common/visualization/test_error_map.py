"""The error map marks exactly the wrong voxels, by kind."""
import numpy as np
import pytest

from projects.occ_common.visualization import (ERROR_PALETTE, error_counts,
                                               occupancy_errors, render_bev)


def _pair():
    """Hand-made 8x8x4 GT / prediction (0 = empty, classes 1 and 2).

    ========== ==== ==== =====================================
    voxel      GT   pred code
    ========== ==== ==== =====================================
    (0, 0, 0)  1    1    0 correct
    (1, 1, 1)  2    0    2 false negative
    (2, 2, 2)  1    2    3 wrong class
    (5, 5, 1)  0    1    1 false positive
    (3, 3, 3)  255  1    0 GT ignored
    (4, 4, 0)  2    0    0 outside the camera mask
    ========== ==== ==== =====================================
    """
    gt = np.zeros((8, 8, 4), dtype=np.int64)
    pred = np.zeros_like(gt)
    gt[0, 0, 0] = pred[0, 0, 0] = 1
    gt[1, 1, 1] = 2
    gt[2, 2, 2], pred[2, 2, 2] = 1, 2
    pred[5, 5, 1] = 1
    gt[3, 3, 3], pred[3, 3, 3] = 255, 1
    gt[4, 4, 0] = 2
    mask = np.ones_like(gt, dtype=bool)
    mask[4, 4, 0] = False
    return pred, gt, mask


def test_codes_of_every_voxel():
    """Only the three wrong voxels of the table are non-zero."""
    pred, gt, mask = _pair()
    codes = occupancy_errors(pred, gt, 3, empty_label=0, mask=mask)
    expected = np.zeros((8, 8, 4), dtype=np.uint8)
    expected[1, 1, 1], expected[2, 2, 2], expected[5, 5, 1] = 2, 3, 1
    np.testing.assert_array_equal(codes, expected)
    assert error_counts(codes) == {
        'false positive': 1, 'false negative': 1, 'wrong class': 1}


def test_without_mask_the_masked_voxel_is_a_false_negative():
    """(4, 4, 0): GT 2, pred 0, now counted -> code 2; 2 FNs in all."""
    pred, gt, _ = _pair()
    codes = occupancy_errors(pred, gt, 3, empty_label=0)
    assert codes[4, 4, 0] == 2
    assert error_counts(codes)['false negative'] == 2


def test_error_bev_colours_the_wrong_columns():
    """Column (5, 5) (FP) -> row 2, col 2 in the error palette's red."""
    pred, gt, mask = _pair()
    codes = occupancy_errors(pred, gt, 3, empty_label=0, mask=mask)
    image = render_bev(codes, ERROR_PALETTE, empty_label=0)
    assert tuple(image[2, 2]) == tuple(ERROR_PALETTE[1])
    assert tuple(image[6, 6]) == tuple(ERROR_PALETTE[2])  # (1, 1): FN
    assert (image != 255).any(axis=2).sum() == 3


def test_perfect_and_empty_predictions():
    """pred == GT -> no error; an all-empty pair -> no error either."""
    _, gt, _ = _pair()
    gt[gt == 255] = 0
    assert not occupancy_errors(gt.copy(), gt, 3, 0).any()
    empty = np.zeros((8, 8, 4), dtype=np.int64)
    assert error_counts(occupancy_errors(empty, empty, 3, 0)) == {
        'false positive': 0, 'false negative': 0, 'wrong class': 0}


def test_bad_inputs_are_named():
    """Shape mismatch and a prediction of 255 raise ValueError."""
    pred, gt, _ = _pair()
    with pytest.raises(ValueError, match='differ in shape'):
        occupancy_errors(pred[:4], gt, 3, 0)
    with pytest.raises(ValueError, match=r'pred_occ: labels \[255\]'):
        occupancy_errors(np.full_like(gt, 255), gt, 3, 0)
