"""Tests of the LiDAR point branch (eqs. 2-4)."""
import pytest
import torch
import torch.nn.functional as F

from projects.occ_common.geometry.depth import project_points
from projects.occ_common.synthetic.occ_inputs import ring_camera_rig
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


def test_input_norm_makes_the_branch_blind_to_attribute_scales():
    """With input_norm a training batch is normalised per attribute before
    the first layer: intensities given as 100 i + 7 (0-255 counts instead
    of a 0-1 reflectance) give the same features; without it they do
    not. One point still trains (the running statistics normalise it)."""
    gen = torch.Generator().manual_seed(0)
    pts = torch.randn(50, 5, generator=gen)
    rescaled = pts.clone()
    rescaled[:, 3] = 100 * pts[:, 3] + 7
    ctx = torch.zeros(1, 4, 1, 2, 4)
    outs = {}
    for input_norm in (False, True):
        torch.manual_seed(0)
        branch = _branch(with_image_features=False, input_norm=input_norm)
        outs[input_norm] = [
            branch([p], ctx, _rig()[None], (32, 64), [(32, 64)])[0]
            for p in (pts, rescaled)
        ]
    torch.testing.assert_close(*outs[True], rtol=1e-4, atol=1e-4)
    assert (outs[False][0] - outs[False][1]).abs().max() > 0.1
    one = branch([pts[:1]], ctx, _rig()[None], (32, 64), [(32, 64)])[0]
    one.sum().backward()
    norm = branch.geo_mlp[0]
    assert isinstance(norm, torch.nn.BatchNorm1d) and norm.num_features == 7
    assert norm.weight.grad is not None


def test_bad_points_raise():
    """Points with the wrong width name the sample."""
    branch = _branch()
    with pytest.raises(ValueError, match='sample 0'):
        branch([torch.zeros(3, 4)], torch.zeros(1, 4, 1, 2, 4),
               _rig()[None], (32, 64), [(32, 64)])
    with pytest.raises(ValueError, match='2 point clouds'):
        branch([torch.zeros(3, 5)] * 2, torch.zeros(1, 4, 1, 2, 4),
               _rig()[None], (32, 64), [(32, 64)])


def _sample_every_camera(xyz, feats, lidar2img, input_shape, img_shape):
    """Reference: sample every point in every camera, then mask (the
    implementation before the visible-only sampling)."""
    uv, depth = project_points(xyz, lidar2img)
    visible = (depth >= 0.1) & (uv[..., 0] >= 0) & \
        (uv[..., 0] < img_shape[1]) & (uv[..., 1] >= 0) & \
        (uv[..., 1] < img_shape[0])
    grid = torch.stack([uv[..., 0] / input_shape[1] * 2 - 1,
                        uv[..., 1] / input_shape[0] * 2 - 1], dim=-1)
    grid = torch.where(visible[..., None], grid, torch.zeros_like(grid))
    sampled = F.grid_sample(feats, grid.unsqueeze(1), align_corners=False)
    sampled = sampled[:, :, 0].permute(0, 2, 1)
    weight = visible.to(feats.dtype).unsqueeze(-1)
    return (sampled * weight).sum(dim=0) / weight.sum(dim=0).clamp(min=1.0)


def _random_scene(seed, num_points=300):
    """Points around the 4-camera rig (some behind or beside every camera,
    some seen by two), random 3-channel maps."""
    gen = torch.Generator().manual_seed(seed)
    xyz = (torch.rand(num_points, 3, generator=gen) - 0.5) * torch.tensor(
        [40.0, 40.0, 6.0])
    feats = torch.randn(4, 3, 2, 4, generator=gen, dtype=torch.float64)
    return xyz, feats.requires_grad_(), gen


@pytest.mark.parametrize('img_shape', [(32, 64), (32, 40), (20, 30)])
def test_visible_only_sampling_equals_every_camera(img_shape):
    """Values and the gradient to the maps equal the sample-everything
    path (float64, random points, cropped images so that some cameras see
    few points)."""
    xyz, feats, gen = _random_scene(0)
    out = sample_image_features(xyz.double(), feats, _rig().double(),
                                (32, 64), img_shape)
    ref = _sample_every_camera(xyz.double(), feats, _rig().double(),
                               (32, 64), img_shape)
    assert (ref != 0).any(dim=1).sum() > 50  # many points seen
    torch.testing.assert_close(out, ref, rtol=1e-12, atol=1e-12)
    grad = torch.randn(out.shape, generator=gen, dtype=torch.float64)
    torch.testing.assert_close(
        torch.autograd.grad(out, feats, grad)[0],
        torch.autograd.grad(ref, feats, grad)[0],
        rtol=1e-12,
        atol=1e-12)


def test_only_visible_pairs_are_sampled(monkeypatch):
    """``grid_sample`` sees exactly the visible (camera, point) pairs: for
    the hand-computed points of :func:`test_sample_hand_computed_mean_over_
    cameras` 2 pairs with the full image, 1 with the cropped one (not
    4 cameras x 2 points = 8); none visible gives zeros that still carry
    a (zero) gradient to the maps."""
    sampled = []
    original = F.grid_sample

    def spy(input, grid, *args, **kwargs):
        sampled.append(grid.shape[:-1].numel())
        return original(input, grid, *args, **kwargs)

    monkeypatch.setattr(F, 'grid_sample', spy)
    pts = torch.tensor([[4.0, 4.0, 0.0], [0.0, 0.0, 5.0]])
    sample_image_features(pts, _feature_maps(), _rig(), (32, 64), (32, 64))
    assert sum(sampled) == 2
    sampled.clear()
    sample_image_features(pts, _feature_maps(), _rig(), (32, 64), (32, 40))
    assert sum(sampled) == 1
    sampled.clear()
    feats = _feature_maps().requires_grad_()
    out = sample_image_features(pts[1:], feats, _rig(), (32, 64), (32, 64))
    assert sampled == [] and out.tolist() == [[0.0]]
    out.sum().backward()
    assert not feats.grad.any()
