"""Tests of TPV-Polar-Fusion (eqs. 6-13 and the dynamic fusion)."""
import math

import pytest
import torch

from projects.occ_cyl import CylinderGrid, TPVPolarFusion

PI = math.pi
# dr = 1 m, dtheta = pi / 2, dz = 1 m: voxel (i, j, k) of (r, theta, z).
CYLINDER = CylinderGrid((4, 4, 2), (0.0, -PI, -1.0, 4.0, PI, 1.0))


def _fusion(**kwargs):
    torch.manual_seed(0)
    cfg = dict(cylinder=CYLINDER, cam_channels=2, lidar_channels=3,
               plane_channels=4, num_groups=2)
    cfg.update(kwargs)
    return TPVPolarFusion(**cfg)


def test_camera_voxels_hand_computed():
    """Two pseudo points (1 camera, 2 bins, 1x1 pixel): bin 0 at
    (x, y, z) = (1.5, 0, 0.5) -> r = 1.5, theta = 0, z = 0.5 -> voxel
    (1, 2, 1), flat (1 * 4 + 2) * 2 + 1 = 13; bin 1 at (0, 2.5, -0.5) ->
    r = 2.5, theta = pi / 2 -> voxel (2, 3, 0), flat (2 * 4 + 3) * 2 = 22.
    depth = (0.25, 0.75), context = (2, -4): voxel 13 holds
    0.25 * (2, -4) = (0.5, -1) and voxel 22 holds 0.75 * (2, -4) =
    (1.5, -3). Only these two occupied voxels are returned (no dense
    volume); the naive path gives the same rows."""
    fusion = _fusion()
    depth = torch.tensor([0.25, 0.75]).view(1, 2, 1, 1)
    ctx = torch.tensor([2.0, -4.0]).view(1, 2, 1, 1)
    pts = torch.tensor([[1.5, 0.0, 0.5], [0.0, 2.5, -0.5]]).view(
        1, 1, 2, 1, 1, 3)
    feats, voxels = fusion.camera_voxels(depth, ctx, pts)
    assert voxels.tolist() == [13, 22]
    assert feats.tolist() == [[0.5, -1.0], [1.5, -3.0]]
    naive = _fusion(fused_lift=False).camera_voxels(depth, ctx, pts)
    assert torch.equal(naive[0], feats) and torch.equal(naive[1], voxels)


def test_lidar_voxels_hand_computed_and_batch_offsets():
    """Sample 0: points (1.5, 0, 0.5) with features (1, 2, 3) and
    (1.2, 0.1, 0.2) with (4, 0, -1) share voxel (1, 2, 1) = flat 13 ->
    (4, 2, 3); a point at r = 10 is outside and dropped. Sample 1:
    (0, -0.5, -0.5) (theta = -pi / 2 -> j = 1) with (7, 7, 7) -> voxel
    (0, 1, 0) = flat 2, plus 32 voxels per sample = 34."""
    fusion = _fusion()
    xyz = [torch.tensor([[1.5, 0.0, 0.5], [1.2, 0.1, 0.2], [10., 0., 0.]]),
           torch.tensor([[0.0, -0.5, -0.5]])]
    feats = [torch.tensor([[1., 2., 3.], [4., 0., -1.], [9., 9., 9.]]),
             torch.tensor([[7., 7., 7.]])]
    pooled, voxels = fusion.lidar_voxels(feats, xyz)
    assert voxels.tolist() == [13, 34]
    assert pooled.tolist() == [[4., 2., 3.], [7., 7., 7.]]


def test_clamping_cylinder_pools_outside_points_into_the_border():
    """With a clamping cylinder (PointOcc) the point at r = 10 of the test
    above is not dropped: r is clamped into ring i = 3 (r in [3, 4)), theta
    0 -> j = 2, z = 0 -> k = 1: flat (3 * 4 + 2) * 2 + 1 = 29, features
    (9, 9, 9)."""
    clamped = CylinderGrid(CYLINDER.shape, CYLINDER.cyl_range, clamp=True)
    fusion = _fusion(cylinder=clamped)
    xyz = [torch.tensor([[1.5, 0.0, 0.5], [10., 0., 0.]])]
    feats = [torch.tensor([[1., 2., 3.], [9., 9., 9.]])]
    pooled, voxels = fusion.lidar_voxels(feats, xyz)
    assert voxels.tolist() == [13, 29]
    assert pooled.tolist() == [[1., 2., 3.], [9., 9., 9.]]


def test_plane_gradient_reaches_exactly_the_winning_point():
    """Two pseudo points in one Z group (M = 2 over Z = 2 cells means one
    cell per group, so use the Theta plane: voxels (1, 2, 1) and (1, 3, 1)
    fall in Theta group 1 of cell (r = 1, z = 1)). Context (2, -4) times
    depths 0.25 (bin 0, theta 0 -> j = 2) and 0.75 (bin 1, theta pi / 2 ->
    j = 3): channel 0 is 0.5 vs 1.5, so bin 1 wins; channel 1 is -1 vs -3,
    so bin 0 wins. d(plane channel 0) / d depth = context 2 at bin 1 only,
    d(plane channel 1) / d depth = -4 at bin 0 only."""
    fusion = _fusion()
    depth = torch.tensor([0.25, 0.75]).view(1, 2, 1, 1).requires_grad_()
    ctx = torch.tensor([2.0, -4.0]).view(1, 2, 1, 1)
    pts = torch.tensor([[1.5, 0.0, 0.5], [0.0, 1.5, 0.5]]).view(
        1, 1, 2, 1, 1, 3)
    feats, voxels = fusion.camera_voxels(depth, ctx, pts)
    plane = fusion.cam_pool.group_pool(feats,
                                       CYLINDER.unravel(voxels),
                                       CYLINDER.shape, 1, 2)
    # Channels g * C + c: group 1, channel 0 is channel 2.
    assert plane[0, 2:, 1, 1].tolist() == [1.5, -1.0]
    plane[0, 2, 1, 1].backward()
    assert depth.grad.flatten().tolist() == [0.0, 2.0]
    depth.grad = None
    feats, voxels = fusion.camera_voxels(depth, ctx, pts)
    plane = fusion.cam_pool.group_pool(feats, CYLINDER.unravel(voxels),
                                       CYLINDER.shape, 1, 2)
    plane[0, 3, 1, 1].backward()
    assert depth.grad.flatten().tolist() == [-4.0, 0.0]


def _inputs(batch=2, cams=2, points=(6, 0)):
    gen = torch.Generator().manual_seed(1)
    depth = torch.rand(batch * cams, 3, 2, 2, generator=gen).softmax(1)
    ctx = torch.randn(batch * cams, 2, 2, 2, generator=gen)
    cam_pts = (torch.rand(batch, cams, 3, 2, 2, 3, generator=gen) - 0.5) * 6
    xyz = [(torch.rand(n, 3, generator=gen) - 0.5) * 6 for n in points]
    feats = [torch.randn(n, 3, generator=gen) for n in points]
    return depth, ctx, cam_pts, feats, xyz


def test_forward_fused_planes_and_backward():
    """Both modalities give three fused planes (B, 4, R, Theta),
    (B, 4, Theta, Z), (B, 4, R, Z); a sample without LiDAR points is fine
    and gradients reach depth, context and point features."""
    fusion = _fusion()
    depth, ctx, cam_pts, feats, xyz = _inputs()
    for t in (depth, ctx, *feats):
        t.requires_grad_()
    planes = fusion(depth, ctx, cam_pts, feats, xyz)
    assert [tuple(p.shape) for p in planes] == [(2, 4, 4, 4), (2, 4, 4, 2),
                                                (2, 4, 4, 2)]
    sum(p.square().sum() for p in planes).backward()
    assert depth.grad.abs().sum() > 0 and ctx.grad.abs().sum() > 0
    assert feats[0].grad.abs().sum() > 0
    assert fusion.fusions[0].fuse.conv.weight.grad is not None


@pytest.mark.parametrize('spread', [6.0, 100.0])
def test_padded_camera_voxels_give_the_same_planes(spread):
    """``padded_voxels`` (what compiled code runs: one pooled row per
    point of each cloud) gives the fused planes and gradients of the
    compacted voxels; at a spread of 100 m every point is outside the 4 m
    cylinder (no voxel occupied, no gradient reaches depth or context)."""
    depth, ctx, cam_pts, feats, xyz = _inputs(points=(6, 3))
    cam_pts = cam_pts / 6 * spread
    xyz = [p / 6 * spread for p in xyz]
    results = []
    for padded in (False, True):
        fusion = _fusion(padded_voxels=padded)
        d, c = depth.clone().requires_grad_(), ctx.clone().requires_grad_()
        planes = fusion(d, c, cam_pts, feats, xyz)
        sum((p * torch.arange(p.numel()).view_as(p)).sum()
            for p in planes).backward()
        results.append((planes, d.grad, c.grad))
    (planes, *grads), (padded_planes, *padded_grads) = results
    for a, b in zip(planes, padded_planes):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    for a, b in zip(grads, padded_grads):
        torch.testing.assert_close(a, b, rtol=1e-6, atol=1e-6)
    if spread > 50:
        assert all(float(g.abs().sum()) == 0 for g in padded_grads)


def test_single_modality_and_errors():
    """Camera-only returns the camera planes unfused; missing inputs and
    an M that does not divide the grid are named."""
    depth, ctx, cam_pts, feats, xyz = _inputs()
    cam_only = _fusion(with_lidar=False)
    planes = cam_only(depth, ctx, cam_pts)
    assert planes[0].shape == (2, 4, 4, 4)
    assert not hasattr(cam_only, 'fusions')
    with pytest.raises(ValueError, match='lidar_feats'):
        _fusion()(depth, ctx, cam_pts)
    with pytest.raises(ValueError, match='num_groups=3'):
        _fusion(num_groups=3)
    with pytest.raises(ValueError, match='at least one'):
        _fusion(with_camera=False, with_lidar=False)
    with pytest.raises(ValueError, match='does not match'):
        _fusion().camera_voxels(depth[:1], ctx[:1], cam_pts)
