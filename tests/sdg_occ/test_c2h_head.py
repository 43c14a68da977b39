"""Tests of ``ChannelToHeightHead`` and its FlashOcc channel order."""
import pytest
import torch

from projects.sdg_occ import (ChannelToHeightHead, channels_to_height,
                              height_labels_to_xyz, height_logits_to_xyz)


def test_channel_order_is_flashocc():
    """Channel c = z * num_classes + cls (class fastest), as FlashOcc's
    ``view(..., Dz, num_classes)``; with 3 classes and Dz = 2, channel 4
    is (z=1, cls=1) and channel 2 is (z=0, cls=2)."""
    num_classes, dz = 3, 2
    x = torch.arange(num_classes * dz, dtype=torch.float32).view(
        1, -1, 1, 1).expand(1, -1, 2, 3).contiguous()
    out = channels_to_height(x, num_classes, dz)
    assert out.shape == (1, 3, 2, 2, 3)
    for cls in range(num_classes):
        for z in range(dz):
            assert torch.all(out[0, cls, z] == z * num_classes + cls)
    assert torch.all(out[0, 1, 1] == 4) and torch.all(out[0, 2, 0] == 2)


def test_xyz_layout():
    """logits[b, c, z, y, x] moves to [b, c, x, y, z]."""
    logits = torch.randn(1, 2, 4, 3, 5)
    xyz = height_logits_to_xyz(logits)
    assert xyz.shape == (1, 2, 5, 3, 4)
    assert xyz[0, 1, 4, 2, 3] == logits[0, 1, 3, 2, 4]


def test_labels_from_contiguous_output_match_permuted_argmax():
    """Labels taken on the predictor's own layout equal the argmax of the
    reordered logits, ties included. By hand, 3 classes, Dz = 2, one cell:
    channels (z0: 1, 5, 5 | z1: 7, 2, 7) give class 1 at z0 (the first of
    the tied 5s) and class 0 at z1 (the first of the tied 7s)."""
    x = torch.tensor([1., 5., 5., 7., 2., 7.]).view(1, 6, 1, 1)
    labels = height_labels_to_xyz(x, 3, 2)
    assert labels.shape == (1, 1, 1, 2) and labels.is_contiguous()
    assert labels.flatten().tolist() == [1, 0]
    torch.manual_seed(0)
    # Rounded logits make ties common; Y != X catches a transposed layout.
    x = torch.randn(2, 4 * 3, 5, 7).round()
    ref = height_logits_to_xyz(channels_to_height(x, 3, 4)).argmax(1)
    assert torch.equal(height_labels_to_xyz(x, 3, 4), ref)
    with pytest.raises(ValueError, match='channels_to_height'):
        height_labels_to_xyz(torch.zeros(1, 5, 2, 2), 3, 2)


def _head(**kwargs):
    torch.manual_seed(0)
    return ChannelToHeightHead(
        in_channels=4, num_classes=3, dz=2, mid_channels=8, **kwargs)


def test_loss_suffix_ignore_and_backward():
    """All labels ignored (255): the CE is a connected zero; with labels the
    loss is positive, its key carries the suffix and it back-propagates
    into the head."""
    head = _head()
    x = torch.randn(2, 4, 3, 5, requires_grad=True)  # Y = 3, X = 5
    gt = torch.randint(0, 3, (2, 5, 3, 2))
    off = head.loss(x, torch.full_like(gt, 255))
    assert list(off) == ['loss_focal'] and off['loss_focal'].item() == 0.0
    on = head.loss(x, gt, suffix='_teacher')
    assert on['loss_focal_teacher'] > 0
    on['loss_focal_teacher'].backward()
    assert x.grad.abs().sum() > 0


def test_loss_equals_cross_entropy():
    """gamma = 0 focal loss = mean CE over non-ignored voxels (255)."""
    head = _head()
    x = torch.randn(1, 4, 3, 5)
    gt = torch.randint(0, 3, (1, 5, 3, 2))
    gt[0, 0] = 255
    logits = height_logits_to_xyz(head(x))
    ref = torch.nn.functional.cross_entropy(logits, gt, ignore_index=255)
    assert torch.isclose(head.loss(x, gt)['loss_focal'], ref, atol=1e-6)


def _loss_occ(*losses):
    return dict(type='OccupancyLoss', losses=list(losses))


def test_extra_losses_labels_and_predict():
    """The head hands empty_index 2 to the SCAL term; one key per term."""
    head = _head(
        loss_occ=_loss_occ(
            dict(type='OccFocalLoss', gamma=2.0), dict(type='OccLovaszLoss'),
            dict(type='SceneClassAffinityLoss', mode='geo')),
        empty_index=2)
    assert head.loss_occ.losses[2].empty_index == 2
    x = torch.randn(1, 4, 3, 5)
    gt = torch.randint(0, 3, (1, 5, 3, 2))
    losses = head.loss(x, gt)
    assert set(losses) == {'loss_focal', 'loss_lovasz', 'loss_geo_scal'}
    pred = head.predict(x)
    assert pred.shape == (1, 5, 3, 2) and pred.dtype == torch.long
    assert torch.equal(pred, height_logits_to_xyz(head(x)).argmax(1))


def test_bad_inputs_raise():
    head = _head()
    x = torch.randn(1, 4, 3, 5)
    with pytest.raises(ValueError, match='gt_occ must have shape'):
        head.loss(x, torch.zeros(1, 3, 5, 2, dtype=torch.long))
    with pytest.raises(ValueError, match='distinct'):
        _head(loss_occ=_loss_occ(
            dict(type='OccFocalLoss'), dict(type='OccFocalLoss')))
    with pytest.raises(ValueError, match='has empty_index=1'):
        _head(loss_occ=_loss_occ(
            dict(type='SceneClassAffinityLoss', empty_index=1)))
    with pytest.raises(ValueError, match='channels_to_height'):
        channels_to_height(torch.zeros(1, 5, 2, 2), 3, 2)
