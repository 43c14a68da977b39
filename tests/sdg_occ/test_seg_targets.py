"""Tests of ``downsample_seg_labels``."""
import pytest
import torch

from projects.sdg_occ import downsample_seg_labels


def test_nearest_labelled_return_wins():
    """One 4 x 4 image, stride 2 -> 2 x 2 cells.

    Cell (0, 0): labels 3 at depth 9 and 5 at depth 4 -> 5 (nearer).
    Cell (0, 1): label 7 at depth 2 but unlabelled (255) at depth 1 -> 7
    (unlabelled pixels never win). Cell (1, 0): label 6 without depth ->
    6 (a labelled pixel without depth still beats nothing). Cell (1, 1):
    no label -> 255, or the empty label 0 when one is given.
    """
    seg = torch.full((1, 4, 4), 255, dtype=torch.long)
    depth = torch.zeros(1, 4, 4)
    seg[0, 0, 0], depth[0, 0, 0] = 3, 9.0
    seg[0, 1, 1], depth[0, 1, 1] = 5, 4.0
    seg[0, 0, 2], depth[0, 0, 2] = 7, 2.0
    depth[0, 1, 3] = 1.0
    seg[0, 3, 0] = 6
    depth[0, 3, 3] = 5.0
    out = downsample_seg_labels(seg, depth, 2)
    assert out.tolist() == [[[5, 7], [6, 255]]]
    out = downsample_seg_labels(seg, depth, 2, empty_label=0)
    assert out.tolist() == [[[5, 7], [6, 0]]]


def test_empty_batch_and_all_unlabelled():
    assert downsample_seg_labels(
        torch.zeros(0, 4, 4, dtype=torch.long), torch.zeros(0, 4, 4),
        2).shape == (0, 2, 2)
    out = downsample_seg_labels(
        torch.full((2, 4, 4), 255), torch.ones(2, 4, 4), 4)
    assert out.tolist() == [[[255]], [[255]]]


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match='multiple of downsample'):
        downsample_seg_labels(torch.zeros(1, 4, 6).long(),
                              torch.zeros(1, 4, 6), 4)
    with pytest.raises(ValueError, match='one shape'):
        downsample_seg_labels(torch.zeros(1, 4, 4).long(),
                              torch.zeros(1, 4, 8), 4)
