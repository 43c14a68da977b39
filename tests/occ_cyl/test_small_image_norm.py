"""The small config's from-scratch image branch normalises each view by
itself, the same way in training and test (issue 14).

A trained BatchNorm normalises a training step by the statistics of its
batch, the 6 views of one scene, and the test by running means over the
training scenes; a held-out scene's weather and light then meet statistics
it was not trained with. The small config's GroupNorm has no running
statistics: a view's features depend on that view only.
"""
import math
import os.path as osp

import pytest
import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG_DIR = osp.join(ROOT, 'configs', 'occ_cyl')
SMALL = osp.join(CONFIG_DIR,
                 'occcyl_small_1xb1-12e_surroundocc-nus-synthetic.py')
TINY = osp.join(CONFIG_DIR, 'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')


@pytest.fixture(scope='module')
def views():
    """Six 96 x 160 views of one sample and the same views with views 1-5
    darkened (another scene's light). Shape (1, 6, 3, 96, 160) each."""
    gen = torch.Generator().manual_seed(0)
    imgs = torch.randn(1, 6, 3, 96, 160, generator=gen)
    darker = imgs.clone()
    darker[:, 1:] = 0.5 * darker[:, 1:] - 1.0
    return imgs, darker


def _image_branch(config):
    """The config's ``img_encoder`` and ``depth_net``."""
    init_default_scope('mmdet3d')
    torch.manual_seed(0)
    model = MODELS.build(Config.fromfile(config).model)
    return model.img_encoder, model.depth_net


def _features(encoder, depth_net, imgs, train):
    """View 0's context features and depth from 6 views at stride 16, in
    training (``train``) or test mode; the DepthNet's BN1d of the camera
    parameters stays in test mode (it normalises the rig's intrinsics and
    extrinsics, which every scene shares).

    Returns:
        tuple[Tensor]: Shapes (C, h, w) and (D, h, w).
    """
    encoder.train(train)
    depth_net.train(train)
    depth_net.cam_param_norm.eval()
    cam_params = torch.linspace(0.0, 1.0, 6 * 22).reshape(6, 22)
    with torch.no_grad():
        feats = encoder(imgs)
        # Any fixed position embedding (it depends on the rig only).
        shape = (6, depth_net.position_channels, *feats.shape[-2:])
        pos_embed = torch.linspace(-1.0, 1.0, math.prod(shape)).reshape(shape)
        out = depth_net(feats, pos_embed, cam_params)
    return out['context'][0], out['depth'][0]


def test_small_image_branch_is_the_same_in_training_and_test(views):
    """Training-mode and test-mode features of a view are equal, and
    view 0's features do not change when the five other views of its step
    do. With the tiny config's BatchNorm (the small config's before this
    change) the test-mode features differ from the training-mode ones
    (by far more than rounding) and darkening views 1-5 moves view 0's
    training-mode features."""
    imgs, darker = views
    encoder, depth_net = _image_branch(SMALL)
    context, depth = _features(encoder, depth_net, imgs, train=True)
    assert context.shape == (16, 6, 10)
    assert depth.shape == (20, 6, 10)  # 20 bins of 2.5 m, stride 16
    for other, train in ((imgs, False), (darker, True), (darker, False)):
        ctx, dep = _features(encoder, depth_net, other, train)
        torch.testing.assert_close(ctx, context, rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(dep, depth, rtol=1e-5, atol=1e-6)

    bn_encoder, bn_depth_net = _image_branch(TINY)
    bn_train, _ = _features(bn_encoder, bn_depth_net, imgs, train=True)
    bn_test, _ = _features(bn_encoder, bn_depth_net, imgs, train=False)
    bn_other, _ = _features(bn_encoder, bn_depth_net, darker, train=True)
    scale = bn_train.abs().mean()
    assert (bn_test - bn_train).abs().mean() > 0.05 * scale
    assert (bn_other - bn_train).abs().mean() > 0.05 * scale
