"""Tests of the cylindrical-to-Cartesian occupancy head (eqs. 17-18)."""
import math

import pytest
import torch
import torch.nn.functional as F

from projects.occ_common.models.layers import cartesian_to_cylindrical
from projects.occ_common.testing.autograd_memory import saved_tensor_bytes
from projects.occ_cyl import CylinderGrid, CylindricalOccHead
from projects.occ_cyl.cylindrical_occ_head import (axis_lerp,
                                                   sample_tpv_planes,
                                                   voxel_centres)

PI = math.pi
PC_RANGE = (-4.0, -4.0, -1.0, 4.0, 4.0, 1.0)
# 8 m / 2 m = 4 x-y cells, 2 m / 1 m = 2 z cells; the cylinder's radius
# reaches the corners at 4 sqrt(2) m.
VOXEL = (2.0, 2.0, 1.0)
CYLINDER = CylinderGrid.covering(PC_RANGE, (4, 8, 2))
LOSS = dict(
    type='MultiScaleOccupancyLoss',
    losses=[dict(type='OccFocalLoss'), dict(type='OccLovaszLoss')])


def _head(**kwargs):
    torch.manual_seed(0)
    cfg = dict(in_channels=3, cylinder=CYLINDER, point_cloud_range=PC_RANGE,
               voxel_size=VOXEL, num_scales=2, hidden_channels=5,
               num_classes=4, loss_occ=LOSS)
    cfg.update(kwargs)
    return CylindricalOccHead(**cfg)


def grid_sample_plane(plane, coords, wrap_h, wrap_w):
    """Reference: ``grid_sample`` (bilinear, border padding) of a plane
    (B, C, H, W) at normalised ``(h, w)`` coords (P, 2) -> (B, C, P); a
    wrapped axis is padded circularly by one cell first (the head's
    sampling before it became separable)."""
    h_coord, w_coord = coords.to(plane.dtype).unbind(-1)
    if wrap_h:
        size = plane.shape[2]
        plane = torch.cat([plane[:, :, -1:], plane, plane[:, :, :1]], dim=2)
        h_coord = ((h_coord + 1) * size + 2) / (size + 2) - 1
    if wrap_w:
        size = plane.shape[3]
        plane = torch.cat([plane[..., -1:], plane, plane[..., :1]], dim=3)
        w_coord = ((w_coord + 1) * size + 2) / (size + 2) - 1
    grid = torch.stack([w_coord, h_coord], dim=-1).view(1, 1, -1, 2)
    return F.grid_sample(plane, grid.expand(plane.shape[0], -1, -1, -1),
                         mode='bilinear', padding_mode='border',
                         align_corners=False)[:, :, 0]


def reference_tpv_samples(planes, cylinder, pc_range, shape):
    """Eq. 17 voxel by voxel: the three planes sampled by grid_sample at
    every voxel centre and summed. Shape (B, X * Y * Z, C)."""
    cyl = cylinder.normalize(
        cartesian_to_cylindrical(voxel_centres(pc_range, shape)))
    wrap = cylinder.full_circle
    feats = 0
    for plane, (ax_h, ax_w) in zip(planes, ((0, 1), (1, 2), (0, 2))):
        feats = feats + grid_sample_plane(plane, cyl[:, [ax_h, ax_w]],
                                          wrap and ax_h == 1,
                                          wrap and ax_w == 1)
    return feats.transpose(1, 2)


def test_axis_lerp_wraps_the_azimuth():
    """Row values (10, 1, 2, 3) along a periodic axis of 4 cells: at
    coord 1 (theta = pi, position t = (2 * 4 - 1) / 2 = 3.5) the sample
    sits half-way between cell 3 and cell 0 -> (3 + 10) / 2 = 6.5, at
    coord -1 (t = -0.5) between cells 3 and 0 too; at 0 (t = 1.5) it is
    (1 + 2) / 2 = 1.5. Without wrapping t is clamped to [0, 3]: 3 and 10.
    """
    row = torch.tensor([10.0, 1.0, 2.0, 3.0])
    coords = torch.tensor([1.0, -1.0, 0.0])

    def lerp(wrap):
        low, up, frac = axis_lerp(coords, 4, wrap)
        return torch.lerp(row[low], row[up], frac)

    torch.testing.assert_close(lerp(True), torch.tensor([6.5, 6.5, 1.5]))
    torch.testing.assert_close(lerp(False), torch.tensor([3.0, 10.0, 1.5]))
    # The reference pads circularly and agrees.
    torch.testing.assert_close(
        grid_sample_plane(row.view(1, 1, 1, 4),
                          torch.stack([torch.zeros(3), coords], 1), False,
                          True), torch.tensor([[[6.5, 6.5, 1.5]]]))


@pytest.mark.parametrize('cylinder', [
    CYLINDER,
    CylinderGrid.for_box(PC_RANGE, (4, 8, 2), 'inscribed', True),
    CylinderGrid((3, 5, 3), (0.0, -PI / 2, -1.5, 6.0, PI / 2, 1.2)),
], ids=['covering', 'clamping', 'half-circle'])
def test_separable_samples_equal_grid_sample_per_voxel(cylinder):
    """The separable sampling gives grid_sample's values at every voxel
    centre, and the same gradients to the three planes, in float64 (to
    1e-12), for two samples of a batch, odd plane sizes, a clamping
    cylinder (voxels beyond its radius take the border) and a half circle
    (no wrap: the azimuth clamps too)."""
    gen = torch.Generator().manual_seed(1)
    shape = (6, 4, 3)
    r, t, z = 5, 7, 4
    planes = [
        torch.randn(2, 3, *hw, generator=gen, dtype=torch.float64,
                    requires_grad=True)
        for hw in ((r, t), (t, z), (r, z))
    ]
    cyl = cylinder.normalize(
        cartesian_to_cylindrical(voxel_centres(PC_RANGE, shape)))
    cyl = cyl.view(shape[0] * shape[1], shape[2], 3)
    got = sample_tpv_planes(planes, cyl[:, 0, :2], cyl[0, :, 2],
                            cylinder.full_circle)
    expected = reference_tpv_samples(planes, cylinder, PC_RANGE, shape)
    assert got.shape == (2, 6 * 4 * 3, 3)
    torch.testing.assert_close(got, expected, rtol=1e-12, atol=1e-12)
    grad = torch.randn(got.shape, generator=gen, dtype=torch.float64)
    for a, b in zip(torch.autograd.grad(got, planes, grad),
                    torch.autograd.grad(expected, planes, grad)):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)


def test_head_projects_before_sampling_with_the_mlp_on_the_sum():
    """The head projects each plane by the MLP's first layer before it
    samples them (a linear map commutes with eq. 17's weighted sum) and
    adds the bias through the (R, Theta) plane, whose bilinear weights sum
    to 1 per voxel. Logits and the gradients to the planes and to every
    MLP parameter equal those of the MLP applied to the summed samples of
    the planes at every voxel (the order of before; the test above checks
    the samples against grid_sample) in float64, to 1e-12, with hidden
    width 5 above and 2 below the 3 plane channels, at both scales."""
    gen = torch.Generator().manual_seed(2)
    for hidden in (5, 2):
        head = _head(hidden_channels=hidden).double()
        sizes = [[(4, 8), (8, 2), (4, 2)], [(2, 4), (4, 1), (2, 1)]]
        planes = [
            tuple(torch.randn(2, 3, *s, generator=gen, dtype=torch.float64,
                              requires_grad=True) for s in lvl)
            for lvl in sizes
        ]
        got = head(planes)
        for level, (x, lvl) in enumerate(zip(got, planes)):
            shape = head.scale_shapes[level]
            columns = getattr(head, f'columns_{level}')
            heights = getattr(head, f'heights_{level}')
            expected = head.classifiers[level](
                sample_tpv_planes(lvl, columns, heights, head.wrap))
            expected = expected.transpose(1, 2).reshape(2, 4, *shape)
            torch.testing.assert_close(x, expected, rtol=1e-12, atol=1e-12)
            params = list(lvl) + list(head.classifiers[level].parameters())
            grad = torch.randn(x.shape, generator=gen, dtype=torch.float64)
            for a, b in zip(torch.autograd.grad(x, params, grad),
                            torch.autograd.grad(expected, params, grad)):
                torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)


def test_scale_shapes_and_loss_labels_come_from_the_head():
    """(8, 8, 2) m over (2, 2, 1) m voxels = (4, 4, 2) at scale 0, halved to
    (2, 2, 1) at scale 1; the loss gets num_scales 2 and the labels."""
    head = _head(empty_index=3, ignore_index=7)
    assert head.scale_shapes == [(4, 4, 2), (2, 2, 1)]
    assert head.loss_occ.num_scales == 2
    assert (head.loss_occ.empty_index, head.loss_occ.ignore_index) == (3, 7)
    assert head.loss_occ.losses[0].ignore_index == 7


def test_voxel_centres():
    """x in [0, 2] with 2 cells -> centres 0.5 and 1.5; y, z one cell -> 1."""
    centres = voxel_centres((0, 0, 0, 2, 2, 2), (2, 1, 1))
    assert centres.tolist() == [[0.5, 1.0, 1.0], [1.5, 1.0, 1.0]]


def test_constant_planes_give_classifier_of_three_times_the_value():
    """Planes constant c = (1, -2, 0.5) per channel: every voxel samples
    c + c + c (eq. 17 sums the three planes), so every logit equals the
    classifier applied to 3 c, at both scales."""
    head = _head().eval()
    c = torch.tensor([1.0, -2.0, 0.5])
    sizes = [[(4, 8), (8, 2), (4, 2)], [(2, 4), (4, 1), (2, 1)]]
    planes = [
        tuple(c.view(1, 3, 1, 1).expand(2, 3, *s).contiguous() for s in lvl)
        for lvl in sizes
    ]
    logits = head(planes)
    assert [tuple(x.shape) for x in logits] == [(2, 4, 4, 4, 2),
                                                (2, 4, 2, 2, 1)]
    for level, x in enumerate(logits):
        expected = head.classifiers[level](3 * c)
        torch.testing.assert_close(
            x.permute(0, 2, 3, 4, 1).reshape(-1, 4),
            expected.expand(x.numel() // 4, 4))
    assert head.predict(logits).shape == (2, 4, 4, 2)
    assert torch.equal(head.predict(logits), logits[0].argmax(1))


def test_loss_and_backward_with_an_all_ignored_sample():
    """The multi-scale loss gives one term per loss and scale; a sample
    whose labels are all 255 contributes nothing but does not fail, and
    gradients reach the planes."""
    head = _head()
    gen = torch.Generator().manual_seed(0)
    sizes = [[(4, 8), (8, 2), (4, 2)], [(2, 4), (4, 1), (2, 1)]]
    planes = [
        tuple(torch.randn(2, 3, *s, generator=gen).requires_grad_()
              for s in lvl) for lvl in sizes
    ]
    gt = torch.randint(0, 4, (2, 4, 4, 2), generator=gen)
    gt[1] = 255
    losses = head.loss(head(planes), gt)
    assert sorted(losses) == [
        'loss_focal_s0', 'loss_focal_s1', 'loss_lovasz_s0', 'loss_lovasz_s1'
    ]
    sum(losses.values()).backward()
    assert all(p.grad is not None for lvl in planes for p in lvl)
    with pytest.raises(ValueError, match='finest grid'):
        head.loss(head(planes), gt[:, :2])


def test_cylinder_must_cover_the_grid():
    """A cylinder of radius 5 < 4 sqrt(2) = 5.66 misses the grid corners."""
    with pytest.raises(ValueError, match='does not cover'):
        _head(cylinder=CylinderGrid((4, 8, 2), (0.0, -PI, -1.0, 5.0, PI,
                                                1.0)))
    with pytest.raises(ValueError, match='2 output scales'):
        _head()([()])


def test_clamping_cylinder_samples_the_border_ring_beyond_its_radius():
    """PointOcc's cylinder of radius 4 (inscribed in the +-4 m box, corners
    at 5.66 m) is accepted when it clamps. Plane (R, Theta) of 4 x 8 cells
    holding the ring index i everywhere, the other planes 0: the corner
    voxel centre (3, 3) at r = 4.24 > 4 samples ring 3 (border), the voxel
    (1, 1) at r = 1.41 samples between rings 1 and 2: r / dr - 0.5 = 0.91
    -> 0.91 (bilinear)."""
    clamped = CylinderGrid.for_box(PC_RANGE, (4, 8, 2), 'inscribed', True)
    head = _head(cylinder=clamped, in_channels=1)
    ring = torch.arange(4.0).view(1, 1, 4, 1).expand(1, 1, 4, 8)
    planes = (ring, torch.zeros(1, 1, 8, 2), torch.zeros(1, 1, 4, 2))
    sampled = sample_tpv_planes(planes, head.columns_0, head.heights_0,
                                True).permute(0, 2, 1)
    xyz = voxel_centres(PC_RANGE, (4, 4, 2))
    r = xyz[:, :2].norm(dim=1)
    corner = (r > 4).nonzero()[0, 0]
    assert sampled[0, 0, corner].item() == pytest.approx(3.0)
    near = (r < 1.5).nonzero()[0, 0]
    assert sampled[0, 0, near].item() == pytest.approx(
        float(r[near]) - 0.5, abs=1e-5)


def test_checkpointed_scales_keep_values_and_gradients():
    """``with_cp`` gives bitwise the same logits, loss and gradients (to
    the planes and every parameter) and keeps less for the backward: the
    plane samples and MLP activations of each scale are recomputed. In
    eval or under no_grad nothing is checkpointed."""
    gen = torch.Generator().manual_seed(3)
    shapes = [((4, 8), (8, 2), (4, 2)), ((2, 4), (4, 1), (2, 1))]
    planes = [[
        torch.randn(2, 3, *hw, generator=gen, dtype=torch.float64)
        for hw in scale
    ] for scale in shapes]
    gt = torch.randint(0, 4, (2, 4, 4, 2), generator=gen)
    results = {}
    for with_cp in (False, True):
        head = _head(with_cp=with_cp).double()
        inputs = [[p.clone().requires_grad_() for p in s] for s in planes]
        logits, saved = saved_tensor_bytes(lambda: head(inputs))
        loss = sum(head.loss(logits, gt).values())
        grads = torch.autograd.grad(
            loss, [p for s in inputs for p in s] + list(head.parameters()))
        results[with_cp] = (logits, loss, grads, saved)
    plain, cp = results[False], results[True]
    assert all(torch.equal(a, b) for a, b in zip(plain[0], cp[0]))
    assert torch.equal(plain[1], cp[1])
    assert all(torch.equal(a, b) for a, b in zip(plain[2], cp[2]))
    assert cp[3] < plain[3] / 2
    with torch.no_grad():
        assert all(
            torch.equal(a, b)
            for a, b in zip(_head(with_cp=True).double()(planes), plain[0]))
