"""Tests of ``SDGViewTransform`` and ``points_to_depth_maps``."""
import math

import pytest
import torch

from projects.occ_common.synthetic.occ_inputs import ring_camera_rig
from projects.sdg_occ import (SDGViewTransform, key_frame_points,
                              points_to_depth_maps, semantic_depth_diffusion)

IMG_SHAPE = (16, 32)  # (H, W); features (2, 4): stride 8
FEAT_SHAPE = (2, 4)
FOCAL = 16.0
# 2.5 m cells; the 0.1 m shift keeps the integer bin depths off the cell
# edges, where float32 and float64 could round to different cells.
PC_RANGE = (-10.1, -10.1, -3.0, 9.9, 9.9, 3.0)
BEV_SHAPE = (8, 8)
DEPTH_BOUND = (1.0, 9.0, 1.0)  # 8 bins at 1 .. 8 m


def _rig(num_cams):
    cam2img, lidar2cam = ring_camera_rig(num_cams, IMG_SHAPE, FOCAL)
    return cam2img, lidar2cam, (cam2img @ lidar2cam).float()


def test_points_to_depth_maps_by_hand(code_path):
    """Camera 0 looks along +x, principal point (16, 8), f = 16, stride 8.

    (10, 0, 0) -> u = 16, v = 8 -> cell (floor(8 / 8), floor(16 / 8))
    = (1, 2), depth 10; (5, 0, 0) hits the same cell nearer -> 5 wins.
    (8, 4, 0): camera x = -4 -> u = 16 - 16 * 4 / 8 = 8 -> cell (1, 1),
    depth 8. (4, 0, 2.5): v = 8 - 16 * 2.5 / 4 = -2 -> above the image.
    (-5, 0, 0) is behind the camera. Sample 1 has no point -> zeros.
    """
    _, _, lidar2img = _rig(1)
    pts = torch.tensor([[10., 0., 0., 1., 0.], [5., 0., 0., 1., 0.],
                        [8., 4., 0., 1., 0.], [4., 0., 2.5, 1., 0.],
                        [-5., 0., 0., 1., 0.]])
    depth = points_to_depth_maps([pts, torch.zeros(0, 5)],
                                 lidar2img[None].expand(2, -1, -1, -1),
                                 IMG_SHAPE, FEAT_SHAPE)
    expected = torch.zeros(2, 2, 4)
    expected[0, 1, 1] = 8.0
    expected[0, 1, 2] = 5.0
    assert torch.equal(depth, expected)


def _naive_bev(context, prob, ext, lidar2cam, cam2img, vt, num_cams):
    """Reference lift with per-pixel loops and the closed-form pinhole.

    A pixel (i, j) sits at u = (j + 0.5) * 8, v = (i + 0.5) * 8;
    at depth d its camera point is ((u - cx) d / f, (v - cy) d / f, d),
    mapped to the LiDAR frame by inv(lidar2cam). A pixel with an extended
    depth d lifts the 2 l + 1 depths d + k r / l (k = -l .. l) in front of
    the camera, each with the distribution interpolated at it (clamped to
    the end bins), rescaled so that they sum to the pixel's mass.
    """
    num_m, chans, feat_h, feat_w = context.shape
    batch = num_m // num_cams
    bev = torch.zeros(batch, chans, *BEV_SHAPE, dtype=torch.float64)
    mask = torch.zeros(batch, 1, *BEV_SHAPE, dtype=torch.bool)
    count = 0
    dmin, _, step = DEPTH_BOUND
    num_bins = prob.shape[1]
    layers = [k * vt.layer_radius / vt.num_layers
              for k in range(-vt.num_layers, vt.num_layers + 1)]
    for m in range(num_m):
        cam2lidar = torch.linalg.inv(lidar2cam[m % num_cams])
        fx, cx, cy = (float(cam2img[m % num_cams, 0, 0]),
                      float(cam2img[m % num_cams, 0, 2]),
                      float(cam2img[m % num_cams, 1, 2]))
        for i in range(feat_h):
            for j in range(feat_w):
                u, v = (j + 0.5) * 8, (i + 0.5) * 8
                if ext[m, i, j] > 0:
                    cands = []
                    for off in layers:
                        d = float(ext[m, i, j]) + off
                        if d <= 0:
                            continue
                        pos = min(max((d - dmin) / step, 0), num_bins - 1)
                        k = min(int(math.floor(pos)), num_bins - 1)
                        t = pos - k
                        p_hi = prob[m, min(k + 1, num_bins - 1), i, j]
                        cands.append((d, (1 - t) * prob[m, k, i, j] +
                                      t * p_hi))
                    total = sum(float(w) for _, w in cands)
                    mass = float(prob[m, :, i, j].sum())
                    cands = [(d, float(w) / total * mass) for d, w in cands]
                elif vt.fallback == 'lss':
                    cands = [(dmin + k * step, prob[m, k, i, j])
                             for k in range(num_bins)]
                else:
                    cands = []
                for d, w in cands:
                    cam = torch.tensor([(u - cx) * d / fx, (v - cy) * d / fx,
                                        d, 1.0], dtype=torch.float64)
                    x, y, z = (cam2lidar @ cam)[:3].tolist()
                    ix = math.floor((x - PC_RANGE[0]) / 2.5)
                    iy = math.floor((y - PC_RANGE[1]) / 2.5)
                    if not (0 <= ix < 8 and 0 <= iy < 8
                            and PC_RANGE[2] <= z < PC_RANGE[5]):
                        continue
                    b = m // num_cams
                    bev[b, :, iy, ix] += float(w) * context[m, :, i,
                                                            j].double()
                    mask[b, 0, iy, ix] = True
                    count += 1
    return bev.float(), mask, count


def _inputs(num_cams=2, seed=0):
    gen = torch.Generator().manual_seed(seed)
    context = torch.randn(num_cams, 3, *FEAT_SHAPE, generator=gen)
    prob = torch.randn(num_cams, 8, *FEAT_SHAPE, generator=gen).softmax(1)
    seg_logits = torch.zeros(num_cams, 3, *FEAT_SHAPE)
    seg_logits[:, 1] = 1.0  # class 1 everywhere ...
    seg_logits[:, 2, :, 0] = 2.0  # ... but class 2 in column 0
    # Camera 0 looks along +x, camera 1 along -x (ring of 2).
    pts = torch.tensor([[5.0, 0.0, 0.0, 1.0, 0.0], [-3.0, 0.5, 0.2, 1.0,
                                                    0.0]])
    return context, prob, seg_logits, [pts]


@pytest.mark.parametrize('fallback', ['lss', 'none'])
def test_sdg_lift_matches_naive_loop(fallback, code_path):
    """SDG points (r = 1 m, l = 1: 3 points) plus the LSS fallback equal
    the loop.

    With radius 1 the return at cell (1, 2) of camera 0 spreads to its
    class-1 neighbours (0, 2), (1, 1), (1, 3); column 0 is class 2 and
    stays without depth, as do the pixels out of reach.
    """
    cam2img, lidar2cam, lidar2img = _rig(2)
    context, prob, seg_logits, points = _inputs()
    vt = SDGViewTransform(PC_RANGE, BEV_SHAPE, DEPTH_BOUND,
                          diffusion_radius=1.0, layer_radius=1.0,
                          num_layers=1, fallback=fallback)
    out = vt(context, prob, seg_logits, points, lidar2img[None], IMG_SHAPE)
    sparse = points_to_depth_maps(points, lidar2img[None], IMG_SHAPE,
                                  FEAT_SHAPE)
    ext = semantic_depth_diffusion(sparse, seg_logits.argmax(1), 1.0)
    assert torch.equal(out['ext_depth'], ext)
    assert ext[0, 1, 2] == 5.0
    assert (ext[0] > 0).sum() == 4 and (ext[0, :, 0] == 0).all()
    ref, ref_mask, count = _naive_bev(context, prob, ext, lidar2cam.double(),
                                      cam2img.double(), vt, 2)
    assert torch.allclose(out['bev'], ref, atol=1e-5)
    assert torch.equal(out['bev_mask'], ref_mask)
    assert int(out['num_sdg_points'] + out['num_lss_points']) == count
    if fallback == 'none':
        assert out['num_lss_points'] == 0


def test_guidance_depth_is_the_key_frame_only(code_path):
    """A car at 5 m on camera 0's axis; 0.45 s earlier (time lag 0.45, a
    merged sweep) its return was at 3.5 m. Column 4 is the time lag: the
    sparse depth of cell (1, 2) is 5 (the key frame), not 3.5, and so is
    the diffused depth around it. A sample without a time column (None)
    uses every point, and a points_time_dims entry past the columns is
    refused."""
    _, _, lidar2img = _rig(2)
    context, prob, seg_logits, _ = _inputs()
    pts = torch.tensor([[5.0, 0.0, 0.0, 1.0, 0.0], [3.5, 0.0, 0.0, 1.0,
                                                    0.45]])
    vt = SDGViewTransform(PC_RANGE, BEV_SHAPE, DEPTH_BOUND,
                          diffusion_radius=1.0)
    out = vt(context, prob, seg_logits, [pts], lidar2img[None], IMG_SHAPE,
             points_time_dims=[4])
    assert out['sparse_depth'][0, 1, 2] == 5.0
    assert out['ext_depth'][0, 1, 3] == 5.0
    assert (out['sparse_depth'] > 0).sum() == 1
    out = vt(context, prob, seg_logits, [pts], lidar2img[None], IMG_SHAPE,
             points_time_dims=[None])
    assert out['sparse_depth'][0, 1, 2] == 3.5
    assert key_frame_points([pts], [4])[0].tolist() == [pts[0].tolist()]
    with pytest.raises(ValueError, match='no time column 5'):
        key_frame_points([pts], [5])


def test_plain_lss_baseline_matches_naive_loop_and_caches():
    """use_sdg=False lifts every pixel over all 8 bins; the second call on
    the same rig reuses the cached frustum indices."""
    cam2img, lidar2cam, lidar2img = _rig(2)
    context, prob, _, points = _inputs(seed=1)
    vt = SDGViewTransform(PC_RANGE, BEV_SHAPE, DEPTH_BOUND, use_sdg=False)
    out = vt(context, prob, None, points, lidar2img[None], IMG_SHAPE)
    no_ext = torch.zeros(2, *FEAT_SHAPE)
    ref, ref_mask, count = _naive_bev(context, prob, no_ext,
                                      lidar2cam.double(), cam2img.double(),
                                      vt, 2)
    assert torch.allclose(out['bev'], ref, atol=1e-5)
    assert torch.equal(out['bev_mask'], ref_mask)
    assert out['num_lss_points'] == count and out['num_sdg_points'] == 0
    vt(context, prob, None, points, lidar2img[None], IMG_SHAPE)
    assert vt.lss_cache.misses == 1 and vt.lss_cache.hits == 1


def test_no_points_and_backward(code_path):
    """No LiDAR point: SDG adds nothing; with fallback 'none' the BEV is
    empty, yet backward runs (zero gradient); with 'lss' gradients reach
    the context features and the depth distribution."""
    _, _, lidar2img = _rig(2)
    context, prob, seg_logits, _ = _inputs()
    context.requires_grad_(True)
    prob.requires_grad_(True)
    vt = SDGViewTransform(PC_RANGE, BEV_SHAPE, DEPTH_BOUND, fallback='none')
    out = vt(context, prob, seg_logits, [torch.zeros(0, 5)], lidar2img[None],
             IMG_SHAPE)
    assert out['bev'].abs().sum() == 0 and not out['bev_mask'].any()
    assert out['num_sdg_points'] == 0 and out['num_lss_points'] == 0
    out['bev'].sum().backward()
    assert context.grad.abs().sum() == 0

    vt = SDGViewTransform(PC_RANGE, BEV_SHAPE, DEPTH_BOUND)
    out = vt(context, prob, seg_logits, _inputs()[3], lidar2img[None],
             IMG_SHAPE)
    out['bev'].pow(2).sum().backward()
    assert context.grad.abs().sum() > 0 and prob.grad.abs().sum() > 0


def test_bad_inputs_raise():
    _, _, lidar2img = _rig(2)
    context, prob, seg_logits, points = _inputs()
    with pytest.raises(ValueError, match='fallback'):
        SDGViewTransform(PC_RANGE, BEV_SHAPE, DEPTH_BOUND, fallback='all')
    with pytest.raises(ValueError, match='use_sdg=False'):
        SDGViewTransform(PC_RANGE, BEV_SHAPE, DEPTH_BOUND, use_sdg=False,
                         fallback='none')
    vt = SDGViewTransform(PC_RANGE, BEV_SHAPE, DEPTH_BOUND)
    with pytest.raises(ValueError, match='depth_prob'):
        vt(context, prob[:, :4], seg_logits, points, lidar2img[None],
           IMG_SHAPE)
    with pytest.raises(ValueError, match='seg_logits'):
        vt(context, prob, None, points, lidar2img[None], IMG_SHAPE)
    with pytest.raises(ValueError, match='needs the points'):
        vt(context, prob, seg_logits, None, lidar2img[None], IMG_SHAPE)
    with pytest.raises(ValueError, match='point clouds'):
        points_to_depth_maps(points * 2, lidar2img[None], IMG_SHAPE,
                             FEAT_SHAPE)


def test_gpu_path_equals_cpu_path():
    """Two samples of 4 cameras and 40 random points, a third of them
    from an earlier sweep: the GPUs' path (nearest depth by a min-scatter,
    the key frame by a mask, every virtual point pooled with the invalid
    ones in the drop cell, the diffusion's windows stacked) gives the CPU
    path's depth maps exactly and its BEV, mask, point counts and
    gradients to float rounding."""
    from projects.occ_common.utils.device_path import forced_accelerator_path
    _, _, lidar2img = _rig(4)
    lidar2img = lidar2img[None].expand(2, -1, -1, -1)
    gen = torch.Generator().manual_seed(3)
    points = []
    for _ in range(2):
        pts = torch.rand(40, 5, generator=gen) * torch.tensor(
            [20.0, 20.0, 4.0, 1.0, 1.0]) - torch.tensor(
                [10.0, 10.0, 2.0, 0.0, 0.0])
        pts[:, 4] = (pts[:, 4] < 0.33).float() * 0.45
        points.append(pts)
    context = torch.randn(8, 3, *FEAT_SHAPE, generator=gen)
    prob = torch.randn(8, 8, *FEAT_SHAPE, generator=gen).softmax(1)
    seg_logits = torch.randn(8, 3, *FEAT_SHAPE, generator=gen)
    outs, grads = [], []
    for gpu in (False, True):
        vt = SDGViewTransform(PC_RANGE, BEV_SHAPE, DEPTH_BOUND,
                              diffusion_radius=1.5, num_layers=2)
        ctx, prb = context.clone().requires_grad_(), \
            prob.clone().requires_grad_()
        with forced_accelerator_path(gpu):
            out = vt(ctx, prb, seg_logits, points, lidar2img, IMG_SHAPE,
                     points_time_dims=[4, 4])
        (out['bev'] * torch.arange(out['bev'].numel()).view_as(
            out['bev']).sin()).sum().backward()
        outs.append(out)
        grads.append((ctx.grad, prb.grad))
    cpu, gpu = outs
    assert (cpu['sparse_depth'] > 0).sum() > 5
    assert torch.equal(gpu['sparse_depth'], cpu['sparse_depth'])
    torch.testing.assert_close(gpu['ext_depth'], cpu['ext_depth'])
    torch.testing.assert_close(gpu['bev'], cpu['bev'])
    assert torch.equal(gpu['bev_mask'], cpu['bev_mask'])
    for key in ('num_sdg_points', 'num_lss_points'):
        assert int(gpu[key]) == int(cpu[key]) > 0, key
    for new, old in zip(grads[1], grads[0]):
        torch.testing.assert_close(new, old)
