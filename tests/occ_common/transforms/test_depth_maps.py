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


def test_semantic_maps_from_occupancy_without_lidarseg(monkeypatch):
    """No ``pts_semantic_mask``: the key-frame points take their voxel's
    label. A grid of 1 m voxels over x, y in [-1, 1), z in [0, 8): column
    (x >= 0, y < 0) is car (4) up to z = 2, vegetation (16) above; the
    rest is empty (0). Point 0 (0, 0, 2) is in voxel (1, 1, 2): empty ->
    no label at pixel (2, 2), so point 1 (0, 0, 4) behind it, also empty,
    leaves it 255; point 2 (0.5, -0.5, 1) is in (1, 0, 1): car -> pixel
    (1, 3) = 4. The sweep point 5 (-0.5, 0.5, 1) would land on empty
    anyway. Moving the car column to (x < 0, y >= 0) labels only the sweep
    point's voxel, which stays unlabelled: key frame only. The fallback is
    logged once, and lidarseg's labels win when both are there."""
    from projects.occ_common.transforms import depth_maps
    logged = []
    monkeypatch.setattr(depth_maps, 'print_log',
                        lambda msg, logger: logged.append(msg))
    grid = np.zeros((2, 2, 8), np.uint8)
    grid[1, 0, :2], grid[1, 0, 2:] = 4, 16
    state = dict(_state(POINTS), gt_occ=grid,
                 occ_pc_range=np.array([-1.0, -1, 0, 1, 1, 8]),
                 occ_voxel_size=np.ones(3))
    transform = PointsToSemanticMaps()
    out = transform(dict(state))
    seg = out['gt_seg_2d'][0]
    assert out['seg_2d_source'] == 'occupancy'
    assert seg[1, 3] == 4 and (seg != 255).sum() == 1
    moved = np.zeros_like(grid)
    moved[0, 1] = 4
    assert (transform(dict(state, gt_occ=moved))['gt_seg_2d'] == 255).all()
    assert len(logged) == 1 and 'occupancy labels' in logged[0]
    both = transform(dict(state, pts_semantic_mask=np.full(6, 7)))
    assert both['seg_2d_source'] == 'lidarseg'
    assert both['gt_seg_2d'][0, 2, 2] == 7
    # Neither source (a split without labels): no map, logged once.
    bare = _state(POINTS)
    assert 'gt_seg_2d' not in transform(bare)
    transform(bare)
    assert len(logged) == 2 and 'neither' in logged[1]
