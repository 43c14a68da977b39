"""Tests of SDG-OCC over T frames: ``num_frames``, temporal fusion, cache.

Model and world of ``test_sdg_occ`` (8 x 8 BEV cells of 2 m over
[-8, 8) m, two 64 x 32 cameras, camera BEV width 6).
"""
import numpy as np
import pytest
import torch
from mmdet3d.registry import MODELS

from projects.occ_common.geometry.bev_warp import warp_bev
from projects.occ_common.synthetic.occ_inputs import make_temporal_scene
from tests.sdg_occ.test_sdg_occ import CAM_CHANNELS, PC_RANGE, _batch, _cfg


def _model(variant, **kwargs):
    torch.manual_seed(0)
    return MODELS.build(dict(_cfg(variant), **kwargs))


def translation(tx):
    mat = np.eye(4, dtype=np.float32)
    mat[0, 3] = tx
    return mat


def scene(num_key_frames=3, step=2.0):
    """Key frames of one scene in the T = 2 layout, 2 m forward each (the
    first repeats itself); 2D labels 1 where a point projects."""
    frames = make_temporal_scene(
        num_key_frames, step, num_cams=2, img_shape=(32, 64),
        num_points=(40, ), occ_shape=(8, 8, 4), pc_range=PC_RANGE)
    for _, samples in frames:
        for sample in samples:
            depth = sample.gt_depth
            sample.gt_seg_2d = torch.where(
                depth > 0, torch.ones_like(depth).long(),
                torch.full_like(depth, 255).long())
    return frames


def own_frame(frame):
    """A T = 2 key frame's own (current) inputs, as a single frame."""
    inputs, samples = frame
    return dict(inputs, imgs=inputs['imgs'][:, :2]), samples


def test_one_frame_is_the_single_frame_model():
    """num_frames=1 builds the same parameters (keys and values, same
    seed) and gives bit-identical logits to a model built without it."""
    for variant in ('camera', 'kl'):
        old, new = _model(variant).eval(), _model(variant,
                                                  num_frames=1).eval()
        assert list(old.state_dict()) == list(new.state_dict())
        assert all(torch.equal(a, b) for a, b in zip(
            old.state_dict().values(), new.state_dict().values()))
        inputs, samples = _batch()
        with torch.no_grad():
            assert torch.equal(old(inputs, samples, mode='tensor'),
                               new(inputs, samples, mode='tensor'))
    assert not any(k.startswith('temporal_fusion')
                   for k in _model('camera', num_frames=1).state_dict())


def test_previous_frame_is_warped_into_the_fusion():
    """Set the reduction conv to copy the previous frame's channels (a 1x1
    identity at the kernel centre of input channels C..2C-1, BN in eval
    with mean 0, var 1, eps 1e-30): the fused BEV is then ReLU(warp(BEV of
    t-1)), with the ego 4 m (two 2 m cells) forward, computed here by hand from
    the previous frame alone."""
    model = _model('camera', num_frames=2).eval()
    conv, bn = model.temporal_fusion.reduce[:2]
    with torch.no_grad():
        conv.weight.zero_()
        for c in range(CAM_CHANNELS):
            conv.weight[c, CAM_CHANNELS + c, 1, 1] = 1.0
        bn.reset_parameters()
        bn.reset_running_stats()
    bn.eps = 1e-30  # sqrt(1 + eps) == 1 in float32; torch >= 2.11 refuses 0
    frames = scene(2, step=4.0)
    with torch.no_grad():
        _, cam = model.extract_camera_bev(*frames[1])
        _, own = model.frame_camera_bev(*own_frame(frames[0]))
    expected = warp_bev(own['bev'], torch.from_numpy(translation(-4.0))[None],
                        PC_RANGE).relu()
    assert torch.allclose(cam['bev'], expected, atol=1e-5)
    # Two columns (ix = 6, 7) have no source after driving 4 m: zeros.
    assert cam['bev'][..., 6:].abs().sum() == 0
    assert own['bev'][..., 2:].abs().sum() > 0


def test_two_frames_train_and_distil_the_fused_bev():
    """T = 2 SDG-KL: losses finite; FOAD's loss alone reaches the
    temporal reduction conv (the student is the fused camera BEV); the
    previous frame's images change the prediction."""
    model = _model('kl', num_frames=2).train()
    inputs, samples = scene(2)[1]
    losses = model(inputs, samples, mode='loss')
    assert all(torch.isfinite(v) for v in losses.values())
    losses['loss_distill'].backward()
    assert model.temporal_fusion.reduce[0].weight.grad.abs().sum() > 0
    model.eval()
    with torch.no_grad():
        before = model(inputs, samples, mode='tensor')
        inputs['imgs'][:, 2:] += 1.0  # frame t-1's two views
        after = model(inputs, samples, mode='tensor')
    assert not torch.allclose(before, after)


def test_cache_equals_recomputation_on_a_three_frame_scene():
    """Key frames 0, 1, 2 of one scene (0 repeats itself as its previous
    frame, then 2 m forward per frame). With the cache each frame's image
    backbone runs once (3 calls), without it twice (6 calls); the
    predictions are equal."""
    frames = scene(3)
    results = {}
    for cached in (False, True):
        model = _model('camera', num_frames=2, test_cache=cached).eval()
        calls = []
        model.img_backbone.register_forward_pre_hook(
            lambda *args: calls.append(1))
        with torch.no_grad():
            results[cached] = [model(i, s, mode='tensor') for i, s in frames]
        assert len(calls) == (3 if cached else 6)
    for a, b in zip(results[False], results[True]):
        assert torch.equal(a, b)
    model.train()
    assert model.bev_cache.get(['frame2-0']) is None  # emptied on train()


def test_bad_temporal_inputs_are_refused():
    model = _model('camera', num_frames=2).eval()
    inputs, samples = _batch()  # a single-frame batch of N = 2 views
    with pytest.raises(ValueError, match=r'holds 2 views, expected T \* N'):
        model(inputs, samples, mode='tensor')
    inputs['imgs'] = inputs['imgs'].repeat(1, 2, 1, 1, 1)
    with pytest.raises(ValueError, match='lacks .*prev_cam2img'):
        model(inputs, samples, mode='tensor')
    inputs['imgs'] = inputs['imgs'][:, :3]
    with pytest.raises(ValueError, match=r'\(B, T \* N, 3, H, W\)'):
        model(inputs, samples, mode='tensor')
    with pytest.raises(ValueError, match='num_frames must be >= 1'):
        _model('camera', num_frames=0)
