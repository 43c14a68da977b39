"""Sparse depth maps and 2D semantic maps from projected points."""
import numpy as np
import pytest
from mmdet3d.structures import LiDARPoints

from projects.occ_common.transforms.depth_maps import (PointsToDepthMaps,
                                                       PointsToSemanticMaps)

# Camera looking along +z of the working frame, f = 2, principal point
# (2, 2), 4x4 image: u = 2 x / z + 2, v = 2 y / z + 2.
K4 = np.array([[2.0, 0, 2, 0], [0, 2, 2, 0], [0, 0, 1, 0], [0, 0, 0, 1]])

# x, y, z, intensity, time lag.
POINTS = np.array([
    [0.0, 0.0, 2.0, 0, 0],  # u = v = 2 -> pixel (2, 2), depth 2
    [0.0, 0.0, 4.0, 0, 0],  # same pixel, farther: hidden
    [0.5, -0.5, 1.0, 0, 0],  # u = 3, v = 1 -> pixel (1, 3), depth 1
    [0.0, 0.0, -1.0, 0, 0],  # behind the camera
    [10.0, 0.0, 1.0, 0, 0],  # u = 22: outside
    [-0.5, 0.5, 1.0, 0, 0.05],  # u = 1, v = 3 -> (3, 1), but a sweep point
])


def _state(points, views=1):
    return dict(
        points=LiDARPoints(points, points_dim=points.shape[1]),
        points_time_dim=4,
        lidar2img=np.tile(K4, (views, 1, 1)),
        img_shape=(4, 4))


def test_depth_maps_key_frame_only():
    """Key frame only: pixels (2, 2) = 2 and (1, 3) = 1, the rest 0; with
    all sweeps (or without a time column) also (3, 1) = 1."""
    out = PointsToDepthMaps()(_state(POINTS))['gt_depth']
    assert out.shape == (1, 4, 4) and out.dtype == np.float32
    expected = np.zeros((1, 4, 4), np.float32)
    expected[0, 2, 2], expected[0, 1, 3] = 2.0, 1.0
    np.testing.assert_array_equal(out, expected)
    all_sweeps = PointsToDepthMaps(key_frame_only=False)(_state(POINTS))
    assert all_sweeps['gt_depth'][0, 3, 1] == 1.0
    # Without merged sweeps column 4 is the ring index: all points count.
    no_sweeps = _state(POINTS)
    del no_sweeps['points_time_dim']
    assert PointsToDepthMaps()(no_sweeps)['gt_depth'][0, 3, 1] == 1.0
    assert 'key_frame_only=True' in repr(PointsToDepthMaps())


def test_empty_points_give_zero_maps():
    """No points: a (2, 4, 4) all-zero depth map and an all-255 label map."""
    state = _state(np.zeros((0, 5)), views=2)
    state['pts_semantic_mask'] = np.zeros(0, np.int64)
    assert not PointsToDepthMaps()(state)['gt_depth'].any()
    seg = PointsToSemanticMaps()(state)['gt_seg_2d']
    assert seg.shape == (2, 4, 4) and (seg == 255).all()


def test_semantic_maps_skip_unlabelled_points():
    """Labels (4, 11, 16, 9, 9, 255): pixel (2, 2) gets 4 from the nearer
    point, (1, 3) gets 16; the unlabelled sweep point at (3, 1) leaves 255.
    A nearer unlabelled point in front of a labelled one does not hide it.
    """
    state = _state(POINTS)
    state['pts_semantic_mask'] = np.array([4, 11, 16, 9, 9, 255])
    seg = PointsToSemanticMaps()(state)['gt_seg_2d'][0]
    assert (seg[2, 2], seg[1, 3], seg[3, 1]) == (4, 16, 255)
    assert (seg != 255).sum() == 2
    front = np.vstack([POINTS, [[0.0, 0.0, 0.5, 0, 0]]])  # pixel (2, 2)
    state = _state(front)
    state['pts_semantic_mask'] = np.array([4, 11, 16, 9, 9, 255, 255])
    assert PointsToSemanticMaps()(state)['gt_seg_2d'][0, 2, 2] == 4


def test_label_count_mismatch():
    """Labels not aligned with points raise, naming the sample."""
    state = _state(POINTS)
    state.update(pts_semantic_mask=np.zeros(3, np.int64), token='s7')
    with pytest.raises(ValueError, match='3 labels but there are 6.*s7'):
        PointsToSemanticMaps()(state)
