"""Tests of the LiDAR point branch (eqs. 2-4)."""
import pytest
import torch

from projects.occ_common.testing.occ_inputs import ring_camera_rig
from projects.occ_cyl import LidarPointBranch, sample_image_features


def _rig():
    """4 cameras at yaw 0, 90, 180, 270 deg, f = 16 on 32x64 images (a
    127 deg field of view, so neighbouring cameras overlap)."""
    cam2img, lidar2cam = ring_camera_rig(4, (32, 64), 16.0)
    return (cam2img @ lidar2cam).float()


def _feature_maps():
    """(N=4, C=1, h=2, w=4) maps at stride 16: camera 0 holds 10 y + x,
    camera 1 holds 100 + 10 y + x, cameras 2, 3 hold 1000."""
    y, x = torch.meshgrid(torch.arange(2.), torch.arange(4.), indexing='ij')
    base = 10 * y + x
    return torch.stack([base, 100 + base, base * 0 + 1000,
                        base * 0 + 1000])[:, None]


def test_sample_hand_computed_mean_over_cameras():
    """Point (4, 4, 0): camera 0 sees it at pixel u = 32 - 16 * 4 / 4 = 16,
    v = 16, i.e. feature coords (16 / 16 - 0.5, 16 / 16 - 0.5) = (0.5, 0.5)
    -> bilinear 10 * 0.5 + 0.5 = 5.5; camera 1 (forward +y, right +x) at
    u = 32 + 16 * 4 / 4 = 48, v = 16 -> (2.5, 0.5) -> 107.5. Mean 56.5.
    Point (0, 0, 5) is on every camera's plane (depth 0): invisible -> 0.
    With img_shape (32, 40) (the rest is padding) u = 48 is outside
    camera 1's image, leaving 5.5."""
    pts = torch.tensor([[4.0, 4.0, 0.0], [0.0, 0.0, 5.0]])
    out = sample_image_features(pts, _feature_maps(), _rig(), (32, 64),
                                (32, 64))
    torch.testing.assert_close(out, torch.tensor([[56.5], [0.0]]))
    out = sample_image_features(pts, _feature_maps(), _rig(), (32, 64),
                                (32, 40))
    torch.testing.assert_close(out, torch.tensor([[5.5], [0.0]]))


def test_sample_gradient_and_errors():
    """The gradient of the mean reaches each visible camera's cells with the
    bilinear weights / 2: at (0.5, 0.5) each of camera 0's 4 neighbouring
    cells gets 0.25 / 2 = 0.125."""
    feats = _feature_maps().requires_grad_()
    pts = torch.tensor([[4.0, 4.0, 0.0]])
    sample_image_features(pts, feats, _rig(), (32, 64), (32, 64)).sum() \
        .backward()
    torch.testing.assert_close(feats.grad[0, 0],
                               torch.tensor([[0.125, 0.125, 0, 0],
                                             [0.125, 0.125, 0, 0]]))
    empty = sample_image_features(torch.zeros(0, 3), feats, _rig(), (32, 64),
                                  (32, 64))
    assert empty.shape == (0, 1)
    with pytest.raises(ValueError, match=r'\(4, 4, 4\)'):
        sample_image_features(pts, feats, _rig()[:3], (32, 64), (32, 64))


def _branch(**kwargs):
    torch.manual_seed(0)
    return LidarPointBranch(5, 1, geo_channels=(8, ), out_channels=(6, ),
                            **kwargs)


def test_forward_shapes_empty_sample_and_backward():
    """Sample 0 has 10 points, sample 1 none: features (10, 6) and (0, 6);
    the loss reaches the MLPs and the camera features."""
    branch = _branch()
    ctx = _feature_maps().repeat(1, 1, 1, 1)[None].repeat(2, 1, 1, 1, 1)
    ctx = ctx.float().requires_grad_()
    l2i = _rig()[None].repeat(2, 1, 1, 1)
    gen = torch.Generator().manual_seed(0)
    pts = [torch.randn(10, 5, generator=gen) * 4, torch.zeros(0, 5)]
    out = branch(pts, ctx, l2i, (32, 64), [(32, 64), (32, 64)])
    assert [tuple(o.shape) for o in out] == [(10, 6), (0, 6)]
    out[0].sum().backward()
    assert branch.geo_mlp[0].weight.grad.abs().sum() > 0
    assert ctx.grad.abs().sum() > 0


def test_all_empty_and_lidar_only():
    """No points at all still backpropagates (zeros); without image
    features the branch ignores the cameras."""
    branch = _branch()
    ctx = torch.zeros(1, 4, 1, 2, 4, requires_grad=True)
    out = branch([torch.zeros(0, 5)], ctx, _rig()[None], (32, 64),
                 [(32, 64)])
    assert out[0].shape == (0, 6)
    out[0].sum().backward()
    lidar_only = _branch(with_image_features=False).eval()
    pts = [torch.randn(5, 5)]
    a = lidar_only(pts, ctx, _rig()[None], (32, 64), [(32, 64)])[0]
    b = lidar_only(pts, ctx + 7, _rig()[None], (32, 64), [(32, 64)])[0]
    torch.testing.assert_close(a, b)


def test_one_point_in_training_uses_the_running_statistics():
    """One point cannot give batch statistics: the branch normalises it
    with the running ones (the eval-mode result), leaves them unchanged,
    and the MLP weights still get a gradient."""
    branch = _branch(with_image_features=False)
    ctx = torch.zeros(1, 4, 1, 2, 4)
    pts = [torch.tensor([[1.0, 2.0, 0.5, 0.3, 0.0]])]
    running = branch.geo_mlp[1].running_mean.clone()
    out = branch(pts, ctx, _rig()[None], (32, 64), [(32, 64)])[0]
    assert branch.training and out.shape == (1, 6)
    assert torch.equal(branch.geo_mlp[1].running_mean, running)
    out.sum().backward()
    assert branch.geo_mlp[0].weight.grad.abs().sum() > 0
    expected = branch.eval()(pts, ctx, _rig()[None], (32, 64),
                             [(32, 64)])[0]
    torch.testing.assert_close(out.detach(), expected)


def test_bad_points_raise():
    """Points with the wrong width name the sample."""
    branch = _branch()
    with pytest.raises(ValueError, match='sample 0'):
        branch([torch.zeros(3, 4)], torch.zeros(1, 4, 1, 2, 4),
               _rig()[None], (32, 64), [(32, 64)])
    with pytest.raises(ValueError, match='2 point clouds'):
        branch([torch.zeros(3, 5)] * 2, torch.zeros(1, 4, 1, 2, 4),
               _rig()[None], (32, 64), [(32, 64)])
