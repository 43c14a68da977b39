"""Tests of ``semantic_depth_diffusion`` on hand-made 2D maps."""
import pytest
import torch

from projects.sdg_occ import semantic_depth_diffusion


def _scene():
    """One 5x5 image with two classes and a background LiDAR return."""
    depth = torch.zeros(1, 5, 5)
    depth[0, 0, 0] = 4.0  # class 1
    depth[0, 0, 2] = 8.0  # class 1
    depth[0, 2, 2] = 20.0  # class 2
    depth[0, 4, 4] = 3.0  # background (class 0)
    seg = torch.tensor([[[1, 1, 1, 0, 0], [1, 1, 2, 0, 0], [0, 0, 2, 2, 0],
                         [0, 0, 0, 0, 0], [0, 0, 0, 0, 0]]])
    return depth, seg


def test_same_class_mean_other_class_ignored_and_copoints_kept():
    """Radius 2 on the 5x5 scene of ``_scene``.

    (0,1) class 1: returns (0,0)=4 and (0,2)=8, distances 1 and 1 -> 6.
    (1,0) class 1: (0,0) at d^2=1 counts; (0,2) at d^2=1+4=5>4 does not
    -> 4. (1,1) class 1: (0,0) and (0,2) at d^2=2 -> (4+8)/2 = 6.
    (1,2) class 2: (2,2)=20 at d^2=1; the class-1 return (0,2) at d^2=1 is
    ignored -> 20. (2,3) class 2: (2,2) at d^2=1 -> 20.
    Co-points (0,0)=4, (0,2)=8, (2,2)=20 and the background return
    (4,4)=3 keep their depth; all other (background) pixels stay 0.
    """
    depth, seg = _scene()
    out = semantic_depth_diffusion(depth, seg, radius=2)
    expected = torch.tensor([[[4., 6., 8., 0., 0.], [4., 6., 20., 0., 0.],
                              [0., 0., 20., 20., 0.], [0., 0., 0., 0., 0.],
                              [0., 0., 0., 0., 3.]]])
    assert torch.equal(out, expected)


def test_radius_boundary_is_inclusive():
    """One return 10 m at (0,0), every pixel class 1, 3x3 image.

    Radius 2: d^2 <= 4 reaches (0,1) 1, (0,2) 4, (1,0) 1, (1,1) 2, (2,0) 4;
    (1,2) and (2,1) have d^2 = 5 and (2,2) d^2 = 8 -> 0.
    Radius 1.5 (d^2 <= 2.25): (0,2) and (2,0) at d^2 = 4 drop out too.
    """
    depth = torch.zeros(1, 3, 3)
    depth[0, 0, 0] = 10.0
    seg = torch.ones(1, 3, 3, dtype=torch.long)
    out = semantic_depth_diffusion(depth, seg, radius=2)
    assert torch.equal(
        out,
        torch.tensor([[[10., 10., 10.], [10., 10., 0.], [10., 0., 0.]]]))
    out = semantic_depth_diffusion(depth, seg, radius=1.5)
    assert torch.equal(
        out, torch.tensor([[[10., 10., 0.], [10., 10., 0.], [0., 0., 0.]]]))


def test_radius_zero_keeps_only_copoints_and_images_do_not_mix():
    """Radius 0 changes nothing; a return in image 0 never reaches image 1.

    Image 1 has the same classes but no return, so it stays all 0 even with
    a radius that covers the whole map.
    """
    depth, seg = _scene()
    depth2 = torch.cat([depth, torch.zeros_like(depth)])
    seg2 = torch.cat([seg, seg])
    assert torch.equal(
        semantic_depth_diffusion(depth2, seg2, radius=0), depth2)
    out = semantic_depth_diffusion(depth2, seg2, radius=10)
    assert torch.equal(out[1], torch.zeros(5, 5))
    # All class-1 pixels see both class-1 returns: (4 + 8) / 2 = 6.
    assert out[0, 1, 0] == 6.0 and out[0, 0, 1] == 6.0


def test_empty_inputs_and_backward():
    """No image, and no return at all, give zeros; gradients are exact.

    On the 3x3 map of the boundary test (radius 2) the 10 m return is used
    by itself and by five diffused pixels, each a mean over one return, so
    d(sum)/d(depth[0,0,0]) = 1 + 5 = 6 and the other entries get 0.
    """
    empty = semantic_depth_diffusion(
        torch.zeros(0, 4, 4), torch.zeros(0, 4, 4, dtype=torch.long), 2)
    assert empty.shape == (0, 4, 4)
    no_returns = semantic_depth_diffusion(
        torch.zeros(2, 4, 4), torch.ones(2, 4, 4, dtype=torch.long), 3)
    assert torch.equal(no_returns, torch.zeros(2, 4, 4))

    depth = torch.zeros(1, 3, 3)
    depth[0, 0, 0] = 10.0
    depth.requires_grad_(True)
    seg = torch.ones(1, 3, 3, dtype=torch.long)
    semantic_depth_diffusion(depth, seg, radius=2).sum().backward()
    expected = torch.zeros(1, 3, 3)
    expected[0, 0, 0] = 6.0
    assert torch.equal(depth.grad, expected)


def test_bad_inputs_raise():
    depth = torch.zeros(1, 3, 3)
    with pytest.raises(ValueError, match='same shape'):
        semantic_depth_diffusion(depth, torch.zeros(1, 3, 4).long(), 1)
    with pytest.raises(ValueError, match='integer class map'):
        semantic_depth_diffusion(depth, torch.zeros(1, 3, 3), 1)
    with pytest.raises(ValueError, match='radius'):
        semantic_depth_diffusion(depth, torch.zeros(1, 3, 3).long(), -1)
    with pytest.raises(ValueError, match=r'\(N, H, W\)'):
        semantic_depth_diffusion(torch.zeros(3, 3), torch.zeros(3, 3), 1)
