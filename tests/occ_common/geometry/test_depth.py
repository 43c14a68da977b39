"""Tests of the depth bins and sparse depth maps of ``geometry.depth``."""
import numpy as np
import pytest
import torch

from projects.occ_common.geometry.depth import (depth_bin_coordinate,
                                                depth_bin_values,
                                                depth_to_bins,
                                                nearest_depth_map,
                                                normalize_depth_bound,
                                                patch_min_depth,
                                                project_nearest,
                                                project_points)
from projects.occ_common.synthetic.occ_inputs import (PATCH_DEPTH_BOUND,
                                                      patch_depth_map,
                                                      ring_camera_rig)

# Camera looking along +z of the working frame, f = 2, principal point
# (2, 2), 4x4 image: u = 2 x / z + 2, v = 2 y / z + 2.
K4 = np.array([[2.0, 0, 2, 0], [0, 2, 2, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
POINTS = np.array([
    [0.0, 0.0, 2.0],  # u = v = 2 -> pixel (2, 2), depth 2
    [0.0, 0.0, 4.0],  # same pixel, farther: hidden
    [0.5, -0.5, 1.0],  # u = 3, v = 1 -> pixel (1, 3), depth 1
    [0.0, 0.0, -1.0],  # behind the camera
    [10.0, 0.0, 1.0],  # u = 22: outside
    [-0.5, 0.5, 1.0],  # u = 1, v = 3 -> pixel (3, 1), depth 1
])

BOUND = PATCH_DEPTH_BOUND  # 4 bins of 1 m from 1 m


def test_patch_min_depth_and_bins():
    """Nearest depth per patch (0 = none) and one-hot bins in (h, w)
    row-major order; only the first and last pixel have a target."""
    nearest = patch_min_depth(patch_depth_map(), 2)
    assert torch.allclose(nearest, torch.tensor([[[2.2, 0.0], [6.0, 1.0]]]))
    onehot, valid = depth_to_bins(patch_depth_map(), 2, BOUND)
    assert onehot.shape == (4, 4)
    assert valid.tolist() == [True, False, False, True]
    assert onehot.tolist() == [[0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0],
                               [1, 0, 0, 0]]


def test_bin_edges():
    """floor((d - 1) / 1): 0.99 -> -1 dropped, 1.0 -> 0, 4.99 -> 3,
    5.0 (= dmax) -> 4 dropped."""
    depth = torch.tensor([[[0.99, 1.0, 4.99, 5.0]]])
    onehot, valid = depth_to_bins(depth, 1, BOUND)
    assert valid.tolist() == [False, True, True, False]
    assert onehot.argmax(1)[valid].tolist() == [0, 3]


def test_depth_bins_follow_the_paper_counts():
    """(1, 51, 1) -> 50 bins 1..50 m (6 x 50 x 58 x 100 points, Table VI);
    (1, 51, 2) -> 25 bins 1, 3, ..., 49; (1, 51, 10) -> 1, 11, 21, 31, 41."""
    assert depth_bin_values((1, 51, 1)).tolist() == list(range(1, 51))
    assert depth_bin_values((1, 51, 2)).tolist() == list(range(1, 50, 2))
    assert depth_bin_values((1, 51, 10)).tolist() == [1, 11, 21, 31, 41]
    with pytest.raises(ValueError, match='depth_bound'):
        depth_bin_values((1, 51))


def test_nearest_bin_removes_the_half_step_bias_of_the_lift():
    """Bins of (1, 11, 2.5) are lifted at 1, 3.5, 6 and 8.5 m. For depths
    uniform in [1, 8.5) BEVDepth's floor trains each onto a point on
    average 1.25 m (half a step) closer, 1.25 m off in absolute value;
    nearest_bin gives mean error 0 and mean absolute error 0.625 m (a
    quarter step). Edges: floor keeps 1 <= d < 11 m, nearest 0 < d < 9.75
    m."""
    bound = (1.0, 11.0, 2.5)
    # 3000 depths at the centres of 2.5 mm steps over [1, 8.5).
    depth = (1.0 + (torch.arange(3000.0) + 0.5) * 2.5e-3).view(1, 1, -1)
    d = depth.flatten()
    for nearest, bias, spread in ((False, -1.25, 1.25), (True, 0.0, 0.625)):
        onehot, valid = depth_to_bins(depth, 1, bound, nearest_bin=nearest)
        assert bool(valid.all())
        lifted = depth_bin_values(bound)[onehot.argmax(1)]
        assert float((lifted - d).mean()) == pytest.approx(bias, abs=1e-4)
        assert float((lifted - d).abs().mean()) == pytest.approx(
            spread, abs=1e-4)
    # 2.3 m: 1.3 m past the 1 m point, 1.2 m before the 3.5 m one.
    edges = torch.tensor([[[0.5, 0.9, 1.2, 2.3, 9.7, 9.8, 10.9]]])
    floor_bins = depth_to_bins(edges, 1, bound)
    near_bins = depth_to_bins(edges, 1, bound, nearest_bin=True)
    assert floor_bins[1].tolist() == [False, False, True, True, True, True,
                                      True]
    assert floor_bins[0].argmax(1)[floor_bins[1]].tolist() == [0, 0, 3, 3, 3]
    assert near_bins[1].tolist() == [True, True, True, True, True, False,
                                     False]
    assert near_bins[0].argmax(1)[near_bins[1]].tolist() == [0, 0, 0, 1, 3]


def test_project_points_empty_and_gradient():
    """No points give (N, 0, 2) pixels; the projection is differentiable:
    u = 32 - 32 y / x at camera 0, so du/dy = -32 / x = -8 at x = 4."""
    cam2img, lidar2cam = ring_camera_rig(2, (32, 64), 32.0)
    l2i = cam2img @ lidar2cam
    uv, depth = project_points(torch.zeros(0, 3, dtype=torch.float64), l2i)
    assert uv.shape == (2, 0, 2) and depth.shape == (2, 0)
    pts = torch.tensor([[4.0, 1.0, 0.0]], dtype=torch.float64,
                       requires_grad=True)
    uv, _ = project_points(pts, l2i)
    uv[0, 0, 0].backward()
    torch.testing.assert_close(pts.grad[0, 1],
                               torch.tensor(-8.0, dtype=torch.float64))
    with pytest.raises(ValueError, match='points'):
        project_points(torch.zeros(3, 2), l2i)


@pytest.mark.parametrize('kind', ['numpy', 'torch'])
def test_project_nearest_by_hand(kind):
    """Two identical views: each keeps pixel (2, 2) at depth 2 (not 4),
    (1, 3) at depth 1 and (3, 1) at depth 1; numpy arrays (the transforms)
    and tensors (the models) give the same answer."""
    points, lidar2img = POINTS[:, :3], np.tile(K4, (2, 1, 1))
    if kind == 'torch':
        points, lidar2img = torch.from_numpy(points), torch.from_numpy(
            lidar2img)
    out = project_nearest(points, lidar2img, (4, 4))
    got = sorted(zip(*(t.tolist() for t in out)))
    assert got == [(0, 1, 3, 1.0, 2), (0, 2, 2, 2.0, 0), (0, 3, 1, 1.0, 5),
                   (1, 1, 3, 1.0, 2), (1, 2, 2, 2.0, 0), (1, 3, 1, 1.0, 5)]
    empty = project_nearest(points[:0], lidar2img, (4, 4))
    assert [len(t) for t in empty] == [0] * 5


def test_numpy_and_torch_agree_on_a_random_cloud():
    """500 points round two cameras, pixel and 1/4 cell maps: the same
    winners, depths equal to float64 rounding."""
    gen = np.random.default_rng(0)
    cam2img, lidar2cam = ring_camera_rig(2, (32, 64), 32.0)
    l2i = (cam2img @ lidar2cam).numpy()
    pts = gen.uniform(-10, 10, (500, 3))
    for map_shape in (None, (8, 16)):
        a = project_nearest(pts, l2i, (32, 64), map_shape=map_shape)
        b = project_nearest(
            torch.from_numpy(pts), torch.from_numpy(l2i), (32, 64),
            map_shape=map_shape)
        assert len(a[0]) > 50
        for x, y in zip(a[:3] + a[4:], b[:3] + b[4:]):
            np.testing.assert_array_equal(x, y.numpy())
        np.testing.assert_allclose(a[3], b[3].numpy(), rtol=1e-12)


SID = (1.0, 5.0, 1.0, 'sid')  # 4 bins, log-spaced from 1 m to 5 - 1 = 4 m


def test_sid_bins_are_bevdets_log_spaced_points():
    """BEVDet's sid=True: D = (5 - 1) / 1 = 4 bins at 1 * 4 ** (k / 3):
    1, 1.5874, 2.5198, 4 m; the coordinate of d is 3 log(d) / log(4), so
    2 m sits at 1.5 (between bins 1 and 2) and every bin point at its
    index. The uniform bound stays 1, 2, 3, 4."""
    torch.testing.assert_close(
        depth_bin_values(SID),
        torch.tensor([1.0, 4**(1 / 3), 4**(2 / 3), 4.0]))
    assert depth_bin_values(SID[:3]).tolist() == [1.0, 2.0, 3.0, 4.0]
    coord = depth_bin_coordinate(torch.tensor([2.0]), SID)
    torch.testing.assert_close(coord, torch.tensor([1.5]))
    torch.testing.assert_close(
        depth_bin_coordinate(depth_bin_values(SID), SID),
        torch.arange(4.0))


def test_sid_targets_floor_the_log_coordinate():
    """BEVDet's sid targets: floor(3 log(d) / log 4). 0.99 m -> -0.02,
    dropped; 1.5 m -> 0.88 -> bin 0; 2.0 -> 1.5 -> 1; 3.9 -> 2.94 -> 2;
    6.0 -> 3.88 -> 3 (the last bin runs to 4 ** (4 / 3) = 6.35 m);
    6.5 -> 4.05 dropped. With nearest_bin (+0.5 before the floor) 0.99 m
    -> 0.48 -> 0, 1.5 -> 1, 2.0 -> 2, 3.9 -> 3.44 -> 3, and 6.0 -> 4.38
    is dropped."""
    depth = torch.tensor([[[0.99, 1.5, 2.0, 3.9, 6.0, 6.5]]])
    onehot, valid = depth_to_bins(depth, 1, SID)
    assert valid.tolist() == [False, True, True, True, True, False]
    assert onehot.argmax(1)[valid].tolist() == [0, 1, 2, 3]
    onehot, valid = depth_to_bins(depth, 1, SID, nearest_bin=True)
    assert valid.tolist() == [True, True, True, True, False, False]
    assert onehot.argmax(1)[valid].tolist() == [0, 1, 2, 3]


def test_depth_bound_spellings():
    """An explicit 'uniform' compares equal to the three numbers; 'sid'
    is kept; other spacings and a SID range without room are refused."""
    assert normalize_depth_bound([1, 5, 1, 'uniform']) == (1.0, 5.0, 1.0)
    assert normalize_depth_bound(SID) == SID
    with pytest.raises(ValueError, match='spacing'):
        normalize_depth_bound((1, 5, 1, 'log'))
    with pytest.raises(ValueError, match="'sid'"):
        normalize_depth_bound((0.0, 5, 1, 'sid'))


def test_bad_depth_bound_and_patch():
    """Patches must tile the map; the bound needs dmin < dmax."""
    with pytest.raises(ValueError, match='multiple of downsample'):
        patch_min_depth(torch.zeros(1, 5, 4), 2)
    with pytest.raises(ValueError, match='dmin < dmax'):
        depth_bin_values((5.0, 1.0, 1.0))


def test_feature_map_of_points_is_the_patch_minimum_of_the_pixel_map():
    """The per-cell map SDG-OCC's view transform builds from the points
    (nearest_depth_map at 1/4 resolution) equals patch_min_depth of the
    per-pixel map the transforms build (the BEVDepth depth target), on a
    random cloud round two cameras: one convention for both."""
    gen = torch.Generator().manual_seed(0)
    cam2img, lidar2cam = ring_camera_rig(2, (32, 64), 32.0)
    l2i = cam2img @ lidar2cam
    pts = torch.cat([
        torch.rand(500, 3, generator=gen, dtype=torch.float64) * 20 - 10,
        torch.rand(500, 2, generator=gen, dtype=torch.float64)
    ], dim=1)
    pixels = nearest_depth_map(pts, l2i, (32, 64), (32, 64), 1e-3)
    cells = nearest_depth_map(pts, l2i, (32, 64), (8, 16), 1e-3)
    assert int((pixels > 0).sum()) > 50
    torch.testing.assert_close(cells, patch_min_depth(pixels, 4))
    empty = nearest_depth_map(pts[:0], l2i, (32, 64), (8, 16))
    assert empty.shape == (2, 8, 16) and not bool(empty.any())
