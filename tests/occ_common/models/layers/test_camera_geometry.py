"""Tests of the frustum, projection and position-embedding helpers."""
import math
import warnings

import pytest
import torch

from projects.occ_common.geometry.depth import project_points
from projects.occ_common.models.layers import (POSITION_EMBED_DIMS,
                                               camera_parameter_vector,
                                               create_frustum,
                                               cylindrical_position_embedding,
                                               frustum_to_lidar,
                                               lidar2img_matrix)
from projects.occ_common.synthetic.occ_inputs import ring_camera_rig


def test_frustum_cell_centres():
    """A 4x8 image with 2x4 features has stride 2: cell (y, x) is centred on
    pixel ((x + 0.5) * 2, (y + 0.5) * 2) = u in {1, 3, 5, 7}, v in {1, 3}
    (pixel i covers [i, i + 1))."""
    fr = create_frustum((4, 8), (2, 4), (2.0, 6.0, 2.0))
    assert fr.shape == (2, 2, 4, 3)
    assert fr[0, 0, :, 0].tolist() == [1.0, 3.0, 5.0, 7.0]
    assert fr[0, :, 0, 1].tolist() == [1.0, 3.0]
    assert fr[:, 0, 0, 2].tolist() == [2.0, 4.0]
    with pytest.raises(ValueError, match='positive'):
        create_frustum((0, 8), (2, 4), (2.0, 6.0, 2.0))


def test_lift_then_project_round_trip():
    """A pixel lifted at depth d projects back to the same pixel and depth.

    Camera 0 of the 2-camera ring looks along +x with f = 32 and principal
    point (32, 16) on a 32x64 image: pixel (u, v) at depth d lifts to
    x = d, y = -(u - 32) * d / 32, z = -(v - 16) * d / 32. For the frustum
    cell at u = 8, v = 8 (stride 16 on a 2x4 map) and d = 4:
    (4, 3, 1).
    """
    cam2img, lidar2cam = ring_camera_rig(2, (32, 64), 32.0)
    aug = torch.eye(4, dtype=torch.float64).repeat(2, 1, 1)
    l2i = lidar2img_matrix(cam2img, lidar2cam, aug)[None]
    frustum = create_frustum((32, 64), (2, 4), (4.0, 8.0, 2.0)).double()
    pts = frustum_to_lidar(frustum, l2i)
    assert pts.shape == (1, 2, 2, 2, 4, 3)
    torch.testing.assert_close(pts[0, 0, 0, 0, 0],
                               torch.tensor([4.0, 3.0, 1.0],
                                            dtype=torch.float64))
    # Camera 1 looks along -x: the same pixel lands at (-4, -3, 1).
    torch.testing.assert_close(pts[0, 1, 0, 0, 0],
                               torch.tensor([-4.0, -3.0, 1.0],
                                            dtype=torch.float64))
    uv, depth = project_points(pts[0, 0].reshape(-1, 3), l2i[0, :1])
    torch.testing.assert_close(uv[0], frustum[..., :2].reshape(-1, 2))
    torch.testing.assert_close(depth[0], frustum[..., 2].reshape(-1))


def test_augmentation_is_inverted_by_the_lift():
    """An image scaled by 2 (pixel (u, v) -> (2u, 2v)) lifts augmented pixel
    (16, 16) at d = 4 to the point that the unaugmented pixel (8, 8) gives:
    (4, 3, 1) for camera 0 (see the round-trip test)."""
    cam2img, lidar2cam = ring_camera_rig(1, (32, 64), 32.0)
    aug = torch.diag(torch.tensor([2.0, 2.0, 1.0, 1.0],
                                  dtype=torch.float64))[None]
    l2i = lidar2img_matrix(cam2img, lidar2cam, aug)[None]
    frustum = torch.tensor([[[[16.0, 16.0, 4.0]]]], dtype=torch.float64)
    pts = frustum_to_lidar(frustum, l2i)
    torch.testing.assert_close(pts.reshape(3),
                               torch.tensor([4.0, 3.0, 1.0],
                                            dtype=torch.float64))
    with pytest.raises(ValueError, match='img_aug_matrix'):
        lidar2img_matrix(cam2img, lidar2cam, aug[:, :3, :3])


def test_position_embedding_values_and_layout():
    """Points (3, 4, 0) and (0, -2, 1) in a cylinder r in [0, 10],
    theta in [-pi, pi], z in [-1, 1] embed as (r / 10, sin theta,
    cos theta, (z + 1) / 2) = (0.5, 0.8, 0.6, 0.5) and (0.2, -1, 0, 1.0);
    bin k's value i sits in channel 4 k + i."""
    pts = torch.tensor([[3.0, 4.0, 0.0], [0.0, -2.0, 1.0]],
                       dtype=torch.float64)
    pts = pts.view(1, 1, 2, 1, 1, 3)  # B, N, D=2, h, w
    emb = cylindrical_position_embedding(pts,
                                         (0, -math.pi, -1, 10, math.pi, 1))
    assert emb.shape == (1, 2 * POSITION_EMBED_DIMS, 1, 1)
    expected = torch.tensor([0.5, 0.8, 0.6, 0.5, 0.2, -1.0, 0.0, 1.0],
                            dtype=torch.float64)
    torch.testing.assert_close(emb.view(-1), expected)
    with pytest.raises(ValueError, match='cyl_range'):
        cylindrical_position_embedding(pts, (0, 0, 0, 1, 1))


def test_position_embedding_has_no_seam_behind_the_left_side():
    """Issue 11, item 3. Two neighbouring feature columns either side of
    theta = +-pi (the car's left in the nuScenes LiDAR frame, seen by
    CAM_BACK_LEFT): points (-10, +0.05, 0) and (-10, -0.05, 0), theta =
    +-(pi - 0.005). Their embeddings differ only in sin theta, by
    2 sin(0.005) = 0.0100; scaled as (theta + pi) / (2 pi) they differed by
    (2 pi - 0.01) / (2 pi) = 0.998. Two columns 0.1 m apart at 10 m on the
    front side (theta = +-0.005) differ by the same 0.0100."""
    pts = torch.tensor([[-10.0, 0.05, 0.0], [-10.0, -0.05, 0.0],
                        [10.0, 0.05, 0.0], [10.0, -0.05, 0.0]],
                       dtype=torch.float64).view(1, 1, 1, 1, 4, 3)
    emb = cylindrical_position_embedding(pts,
                                         (0, -math.pi, -1, 20, math.pi, 1))
    seam = (emb[0, :, 0, 0] - emb[0, :, 0, 1]).abs()
    front = (emb[0, :, 0, 2] - emb[0, :, 0, 3]).abs()
    step = 2 * math.sin(math.atan2(0.05, 10.0))
    torch.testing.assert_close(
        seam, torch.tensor([0.0, step, 0.0, 0.0], dtype=torch.float64))
    torch.testing.assert_close(seam, front)
    assert float(seam.max()) < 0.011


def test_camera_parameter_vector():
    """fx, fy, cx, cy = 32, 32, 32, 16; identity augmentation (rotation
    1, 0, 0, 1 and no shift); camera 0's cam2lidar rotation has the camera
    z axis (forward) along lidar +x: rows (0, 0, 1), (-1, 0, 0), (0, -1, 0)
    and no translation."""
    cam2img, lidar2cam = ring_camera_rig(2, (32, 64), 32.0)
    aug = torch.eye(4, dtype=torch.float64).repeat(2, 1, 1)
    vec = camera_parameter_vector(cam2img[None], lidar2cam[None], aug[None])
    assert vec.shape == (1, 2, 22)
    expected = torch.tensor([
        32, 32, 32, 16, 1, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 0, 0, -1,
        0, 0
    ],
                            dtype=torch.float64)
    torch.testing.assert_close(vec[0, 0], expected, atol=1e-12, rtol=0)


def test_device_frustum_under_compile_skips_the_cache():
    """Compiled (eager backend, one graph), ``device_frustum`` gives the
    frustum's values without Dynamo's warning "Dynamo detected a call to a
    `functools.lru_cache`-wrapped function", which it gave for every
    compiled camera model (Dynamo warns once per process: its record of
    given warnings is cleared first). Eager calls still share one
    tensor."""
    from torch._dynamo import utils as dynamo_utils

    from projects.occ_common.models.layers.camera_geometry import \
        device_frustum

    def lift(x):
        return x + device_frustum((4, 8), (2, 4), (2.0, 6.0, 2.0), 'cpu')

    torch._dynamo.reset()
    dynamo_utils.warn_once_cache.clear()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        out = torch.compile(lift, backend='eager', fullgraph=True)(
            torch.zeros(()))
    assert not [w for w in caught if 'lru_cache' in str(w.message)]
    assert torch.equal(out, create_frustum((4, 8), (2, 4), (2.0, 6.0, 2.0)))
    assert device_frustum((4, 8), (2, 4), (2.0, 6.0, 2.0), 'cpu') is \
        device_frustum((4, 8), (2, 4), (2.0, 6.0, 2.0), 'cpu')
