"""Tests of the cylinder grid spec."""
import math

import pytest
import torch

from projects.occ_common.synthetic.occ_inputs import ring_camera_rig
from projects.occ_cyl.cylindrical import (CylinderGrid,
                                          cartesian_to_cylindrical,
                                          cylindrical_to_cartesian,
                                          pseudo_point_voxels)

PI = math.pi


def _grid():
    # dr = 1 m, dtheta = pi / 2, dz = 1 m.
    return CylinderGrid((4, 4, 2), (0.0, -PI, -1.0, 4.0, PI, 1.0))


def test_voxel_index_hand_computed():
    """(r, theta, z) = (2.5, 0.1, 0.5): i = floor(2.5 / 1) = 2,
    j = floor((0.1 + pi) / (pi / 2)) = 2, k = floor((0.5 + 1) / 1) = 1 ->
    flat ((2 * 4) + 2) * 2 + 1 = 21; in sample 1 add 4 * 4 * 2 = 32 -> 53.
    (0.5, -3, -0.5): i = 0, j = floor(0.14 / 1.57) = 0, k = 0 -> 0."""
    grid = _grid()
    cyl = torch.tensor([[2.5, 0.1, 0.5], [0.5, -3.0, -0.5]])
    coords, inside = grid.voxel_coords(cyl)
    assert coords.tolist() == [[2, 2, 1], [0, 0, 0]]
    assert inside.tolist() == [True, True]
    assert grid.flat_index(cyl).tolist() == [21, 0]
    assert grid.flat_index(cyl, torch.tensor([1, 0])).tolist() == [53, 0]
    assert grid.num_voxels == 32
    assert grid.voxel_size == pytest.approx((1.0, PI / 2, 1.0))


def test_azimuth_wraps_and_outside_is_minus_one():
    """theta = pi is the same direction as -pi: voxel j = 0, not j = 4.
    (1.5, pi, 0) -> (1, 0, 1) -> flat (1 * 4 + 0) * 2 + 1 = 9.
    r = 4 (= r_max), z = 1 (= z_max) and z = -1.5 are outside -> -1."""
    grid = _grid()
    cyl = torch.tensor([[1.5, PI, 0.0], [4.0, 0.0, 0.0], [1.0, 0.0, 1.0],
                        [1.0, 0.0, -1.5]],
                       dtype=torch.float64)
    coords, inside = grid.voxel_coords(cyl)
    assert coords[0].tolist() == [1, 0, 1]
    assert inside.tolist() == [True, False, False, False]
    assert grid.flat_index(cyl).tolist() == [9, -1, -1, -1]


def test_partial_sector_does_not_wrap():
    """With theta in [0, pi/2) an angle of pi/2 is outside (no wrap)."""
    grid = CylinderGrid((2, 2, 1), (0.0, 0.0, 0.0, 2.0, PI / 2, 1.0))
    assert not grid.full_circle
    cyl = torch.tensor([[1.0, PI / 2, 0.5], [1.0, PI / 4 + 0.01, 0.5]])
    assert grid.flat_index(cyl).tolist() == [-1, 3]
    assert not grid.covers_box((-1, -1, 0, 1, 1, 1))


def test_covers_the_output_grid_corners():
    """x, y in [-50, 50]: the corners are 50 * sqrt(2) = 70.71 m away, so a
    70.72 m cylinder covers the grid and a 70.70 m one does not; every voxel
    corner of a 200x200x16 grid then maps inside."""
    box = (-50.0, -50.0, -5.0, 50.0, 50.0, 3.0)
    good = CylinderGrid((128, 256, 16), (0, -PI, -5, 70.72, PI, 3))
    bad = CylinderGrid((128, 256, 16), (0, -PI, -5, 70.70, PI, 3))
    low = CylinderGrid((128, 256, 16), (0, -PI, -4, 70.72, PI, 3))
    assert good.covers_box(box)
    assert not bad.covers_box(box)
    assert not low.covers_box(box)
    xs = torch.linspace(-50, 50, 201)
    zs = torch.linspace(-5, 3 - 1e-4, 17)
    x, y, z = torch.meshgrid(xs, xs, zs, indexing='ij')
    pts = torch.stack([x, y, z], -1).reshape(-1, 3).double()
    _, inside = good.voxel_coords(cartesian_to_cylindrical(pts))
    assert bool(inside.all())


def test_covering_reaches_the_far_corner():
    """x in [-40, 30], y in [-10, 20]: the farthest corner is (-40, 20), at
    (40^2 + 20^2)^0.5 = 44.72 m, plus the 1 cm margin; the height is the
    box's, the azimuth the full circle."""
    grid = CylinderGrid.covering((-40.0, -10.0, -1.0, 30.0, 20.0, 5.4),
                                 (8, 16, 4))
    assert grid.shape == (8, 16, 4)
    assert grid.cyl_range == pytest.approx(
        (0.0, -PI, -1.0, math.hypot(40, 20) + 0.01, PI, 5.4))
    assert grid.full_circle
    assert grid.covers_box((-40.0, -10.0, -1.0, 30.0, 20.0, 5.4))


def test_normalize_and_round_trip():
    """normalize maps the range ends to -1 and 1: r = 2 of [0, 4] -> 0; and a
    voxel centre survives cyl -> cart -> cyl into the same voxel."""
    grid = _grid()
    norm = grid.normalize(torch.tensor([[2.0, -PI, 1.0]]))
    torch.testing.assert_close(norm, torch.tensor([[0.0, -1.0, 1.0]]))
    centres = torch.tensor([[0.5, -PI + PI / 4, -0.5],
                            [3.5, PI - PI / 4, 0.5]])
    back = cartesian_to_cylindrical(cylindrical_to_cartesian(centres))
    assert grid.flat_index(back).tolist() == grid.flat_index(
        centres).tolist()


def test_empty_points_and_gradient_through_normalize():
    """No points -> empty indices; normalize is differentiable with slope
    2 / (r_max - r_min) = 0.5 for r."""
    grid = _grid()
    assert grid.flat_index(torch.zeros(0, 3)).shape == (0, )
    cyl = torch.tensor([[1.0, 0.0, 0.0]], requires_grad=True)
    grid.normalize(cyl)[0, 0].backward()
    torch.testing.assert_close(cyl.grad, torch.tensor([[0.5, 0.0, 0.0]]))


def test_bad_specs_raise():
    """Bad shapes, ranges and an azimuth over 2 pi are refused."""
    with pytest.raises(ValueError, match='shape must be three'):
        CylinderGrid((4, 4), (0, -PI, -1, 4, PI, 1))
    with pytest.raises(ValueError, match='cyl_range'):
        CylinderGrid((4, 4, 2), (0, -PI, -1, 4, PI))
    with pytest.raises(ValueError, match='min < max'):
        CylinderGrid((4, 4, 2), (5, -PI, -1, 4, PI, 1))
    with pytest.raises(ValueError, match='2\\*pi'):
        CylinderGrid((4, 4, 2), (0, -PI, -1, 4, PI + 1, 1))


def test_clamp_puts_outside_points_into_the_border_voxels():
    """PointOcc's clamp on the (4, 4, 2) grid: r = 4 (= r_max) and r = 9
    go to ring i = 3; z = 1 (= z_max) and z = 7 to k = 1, z = -1.5 to
    k = 0; theta still wraps (pi -> j = 0). (9, 0, 7) -> (3, 2, 1) ->
    flat (3 * 4 + 2) * 2 + 1 = 29; (4, pi, -1.5) -> (3, 0, 0) -> 24. Only
    a NaN is outside."""
    grid = CylinderGrid((4, 4, 2), (0.0, -PI, -1.0, 4.0, PI, 1.0),
                        clamp=True)
    cyl = torch.tensor([[9.0, 0.0, 7.0], [4.0, PI, -1.5], [1.0, 0.0, 1.0],
                        [float('nan'), 0.0, 0.0]], dtype=torch.float64)
    coords, inside = grid.voxel_coords(cyl)
    assert coords[:3].tolist() == [[3, 2, 1], [3, 0, 0], [1, 2, 1]]
    assert inside.tolist() == [True, True, True, False]
    assert grid.flat_index(cyl).tolist() == [29, 24, 13, -1]


def test_for_box_inscribed_is_pointocc_cylinder():
    """SurroundOcc's box x, y in [-50, 50], z in [-5, 3]: the inscribed
    radius is 50 m, PointOcc's r in [0, 50]; Occ3D's +-40 m gives 40 m.
    The circumscribed fit is covering()'s 70.72 m."""
    box = (-50.0, -50.0, -5.0, 50.0, 50.0, 3.0)
    grid = CylinderGrid.for_box(box, (480, 368, 32), 'inscribed', True)
    assert grid.cyl_range == pytest.approx((0.0, -PI, -5.0, 50.0, PI, 3.0))
    assert grid.clamp and not grid.covers_box(box)
    occ3d = CylinderGrid.for_box((-40, -40, -1, 40, 40, 5.4), (8, 8, 8),
                                 'inscribed')
    assert occ3d.cyl_range[3] == 40.0 and not occ3d.clamp
    wide = CylinderGrid.for_box(box, (8, 8, 8))
    assert wide.cyl_range[3] == pytest.approx(50 * 2**0.5 + 0.01)
    with pytest.raises(ValueError, match='radius must be one of'):
        CylinderGrid.for_box(box, (8, 8, 8), 'outer')


def test_occupied_compacts_and_unravel_inverts(code_path):
    """Flat indices (21, -1, 0, 21, 53) of the (4, 4, 2) grid: occupied
    voxels (0, 21, 53) and rows (1, -1, 0, 1, 2); 53 = 32 + 21 is voxel
    (2, 2, 1) of sample 1 -> (b, i, j, k) = (1, 2, 2, 1)."""
    grid = _grid()
    voxels, rows = grid.occupied(torch.tensor([21, -1, 0, 21, 53]))
    assert voxels.tolist() == [0, 21, 53]
    assert rows.tolist() == [1, -1, 0, 1, 2]
    assert grid.unravel(voxels).tolist() == [[0, 0, 0, 0], [0, 2, 2, 1],
                                             [1, 2, 2, 1]]
    none, rows = grid.occupied(torch.tensor([-1, -1]))
    assert none.numel() == 0 and rows.tolist() == [-1, -1]


def test_occupied_padded_keeps_one_row_per_point():
    """The example above padded to its 5 points: voxels (0, 21, 53) in
    the first rows, then 2 padding rows (not filled); the same rows
    (1, -1, 0, 1, 2). All outside: nothing filled, rows -1."""
    grid = _grid()
    voxels, rows, filled = grid.occupied_padded(
        torch.tensor([21, -1, 0, 21, 53]))
    assert voxels.shape == (5, ) and voxels[:3].tolist() == [0, 21, 53]
    assert filled.tolist() == [True, True, True, False, False]
    assert rows.tolist() == [1, -1, 0, 1, 2]
    _, rows, filled = grid.occupied_padded(torch.tensor([[-1, -1]]))
    assert not filled.any() and rows.tolist() == [[-1, -1]]


def test_occupied_padded_equals_occupied_on_random_indices():
    """Random flat indices of a (2, 3, 4, 5) batch: the filled rows are
    :meth:`occupied`'s voxels, the rows the same."""
    flat = torch.randint(-1, 40, (2, 3, 4, 5),
                         generator=torch.Generator().manual_seed(0))
    voxels, rows = _grid().occupied(flat)
    padded, padded_rows, filled = _grid().occupied_padded(flat)
    assert int(filled.sum()) == voxels.numel()
    assert torch.equal(padded[:voxels.numel()], voxels)
    assert torch.equal(padded_rows, rows)


def test_pseudo_point_voxels_hand_computed():
    """One camera at the origin looking along +x, a 16 x 16 image seen as a
    1 x 1 feature map (its cell centre is the principal point, so the ray
    is the x axis) and bins (1, 5, 0.5): 8 pseudo points at x = 1, 1.5,
    ..., 4.5 m. In the (4, 4, 2) grid (dr = 1 m, r < 4) they fall in rings
    1, 1, 2, 2, 3, 3 and two beyond 4 m: 8 points, 3 occupied voxels (the
    far two dropped, or clamped into ring 3)."""
    cam2img, lidar2cam = ring_camera_rig(1, (16, 16), focal=16.0)
    lidar2img = cam2img @ lidar2cam
    for clamp in (False, True):
        grid = CylinderGrid((4, 4, 2), (0.0, -PI, -1.0, 4.0, PI, 1.0), clamp)
        assert pseudo_point_voxels(grid, lidar2img, (16, 16), (1, 1),
                                   (1.0, 5.0, 0.5)) == (8, 3)
