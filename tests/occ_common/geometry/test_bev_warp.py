"""Tests of the temporal BEV alignment of ``geometry.bev_warp``.

Grid of every test: 8x8 cells of 1 m over x, y in [-4, 4), so cell
``(iy, ix)`` has its centre at ``(ix - 3.5, iy - 3.5)``.
"""
import math

import numpy as np
import pytest
import torch

from projects.occ_common.geometry.bev_warp import relative_pose, warp_bev

PCR = (-4.0, -4.0, -1.0, 4.0, 4.0, 1.0)


def pose(yaw_deg=0.0, tx=0.0, ty=0.0):
    """A 4x4 ego-to-global pose: yaw about z, then a translation."""
    theta = math.radians(yaw_deg)
    mat = np.eye(4)
    mat[:2, :2] = [[math.cos(theta), -math.sin(theta)],
                   [math.sin(theta), math.cos(theta)]]
    mat[:2, 3] = (tx, ty)
    return mat


def one_hot_bev(iy, ix, channels=2):
    """A (1, C, 8, 8) BEV with value c + 1 in channel c of one cell."""
    bev = torch.zeros(1, channels, 8, 8)
    for c in range(channels):
        bev[0, c, iy, ix] = c + 1.0
    return bev


def warp(bev, prev_pose, curr_pose, **kwargs):
    rel = torch.from_numpy(relative_pose(prev_pose, curr_pose))[None]
    return warp_bev(bev, rel, PCR, **kwargs)


def nonzero_cells(bev):
    return [tuple(c) for c in torch.nonzero(bev[0, 0]).tolist()]


def test_identity_pose_is_identity():
    """prev == curr: every cell reads its own centre, bilinear weight 1."""
    bev = torch.randn(2, 3, 8, 8)
    rel = torch.eye(4).expand(2, 4, 4)
    assert torch.allclose(warp_bev(bev, rel, PCR), bev, atol=1e-6)


def test_pure_translation_moves_static_object_two_cells_back():
    """The ego drives 2 m forward (+x) between frames.

    A static object at previous-frame (2.5, 0.5), cell (iy=4, ix=6), is at
    (2.5 - 2, 0.5) = (0.5, 0.5) in the current frame: cell (4, 4), two
    cells behind, with its features intact in both channels.
    """
    bev = one_hot_bev(4, 6)
    out = warp(bev, pose(), pose(tx=2.0))
    assert nonzero_cells(out) == [(4, 4)]
    assert out[0, :, 4, 4].tolist() == pytest.approx([1.0, 2.0])
    assert out.sum().item() == pytest.approx(3.0)


def test_ninety_degree_left_turn():
    """The ego turns 90 degrees left (yaw +90) in place.

    The current frame is the previous one rotated by +90 degrees, so a
    static point has current coordinates R(-90) p: (x, y) -> (y, -x). The
    object at previous (2.5, 0.5), cell (4, 6), is at current (0.5, -2.5),
    cell (iy = -2.5 + 3.5 = 1, ix = 0.5 + 3.5 = 4).
    """
    out = warp(one_hot_bev(4, 6), pose(), pose(yaw_deg=90.0))
    assert nonzero_cells(out) == [(1, 4)]
    assert out[0, :, 1, 4].tolist() == pytest.approx([1.0, 2.0], abs=1e-5)


def test_turn_and_drive_in_global_frame():
    """Poses away from the origin: prev at (100, 50) facing +x, current
    at (100, 52) facing +y (yaw 90), i.e. 2 m to the previous left.

    Object at previous (2.5, 0.5) is at global (102.5, 50.5); relative to
    the current ego that is (2.5, -1.5), rotated by -90: (-1.5, -2.5),
    cell (iy = 1, ix = 2).
    """
    out = warp(one_hot_bev(4, 6), pose(tx=100, ty=50),
               pose(yaw_deg=90.0, tx=100, ty=52))
    assert nonzero_cells(out) == [(1, 2)]


def test_leaving_the_grid_gives_zeros_and_half_cell_interpolates():
    """Driving 8 m forward moves every previous cell out of the grid; a
    half-cell move (0.5 m) splits a cell bilinearly, 0.5 / 0.5."""
    bev = torch.ones(1, 1, 8, 8)
    assert warp(bev, pose(), pose(tx=8.0)).abs().sum() == 0
    out = warp(one_hot_bev(4, 6, channels=1), pose(), pose(tx=0.5))
    assert out[0, 0, 4, 5].item() == pytest.approx(0.5)
    assert out[0, 0, 4, 6].item() == pytest.approx(0.5)


def test_bda_conjugation_keeps_the_object_aligned():
    """With a BEV flip of x applied to both frames, the object (2.5, 0.5)
    is at augmented (-2.5, 0.5), cell (4, 1); after driving 2 m forward it
    is at (0.5, 0.5) unaugmented, (-0.5, 0.5) augmented: cell (4, 3)."""
    bda = np.diag([-1.0, 1.0, 1.0, 1.0])
    rel = relative_pose(pose(), pose(tx=2.0), bda)
    out = warp_bev(one_hot_bev(4, 1), torch.from_numpy(rel)[None], PCR)
    assert nonzero_cells(out) == [(4, 3)]


def test_gradient_reaches_previous_features_and_bad_shapes_refused():
    bev = torch.randn(1, 2, 8, 8, requires_grad=True)
    warp(bev, pose(), pose(tx=2.0)).sum().backward()
    # Columns ix = 2..7 land inside the grid, 0..1 fall off the back.
    assert bev.grad[0, 0, :, 2:].eq(1).all()
    assert bev.grad[0, 0, :, :2].eq(0).all()
    with pytest.raises(ValueError, match=r'prev2curr must be \(1, 4, 4\)'):
        warp_bev(bev, torch.eye(4), PCR)
    with pytest.raises(ValueError, match='must be 4x4'):
        relative_pose(np.eye(3), np.eye(4))
