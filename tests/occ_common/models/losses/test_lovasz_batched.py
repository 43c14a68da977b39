"""The batched Lovasz coefficients (the GPU path: one sort for all
classes) equal the per-class loop's, and so do the loss and its
gradient."""
import pytest
import torch

from projects.occ_common.models.losses import lovasz_loss as lz
from projects.occ_common.utils.device_path import forced_accelerator_path


@pytest.mark.parametrize('classes', ['present', 'all', [0, 3, 5]])
def test_batched_equals_the_class_loop(classes):
    """1,000 voxels, 6 classes, class 4 absent; probabilities rounded to
    1/8 so that many errors tie (ties must keep voxel order in both)."""
    gen = torch.Generator().manual_seed(0)
    labels = torch.randint(0, 6, (1000, ), generator=gen)
    labels[labels == 4] = 5
    logits = torch.randn(1000, 6, generator=gen)
    probs = (torch.softmax(logits, 1) * 8).round() / 8
    total = torch.bincount(labels, minlength=6)
    columns = torch.tensor([0, 1, 2, 3, 4, 5] if classes == 'all' else
                           ([0, 1, 2, 3, 5] if classes == 'present' else
                            classes))
    want = lz._lovasz_coefficients(probs, labels, total, columns)
    got = lz._lovasz_coefficients_batched(probs, labels, total, columns)
    for a, b in zip(got, want):
        assert torch.allclose(a, b, atol=1e-6)
    probs = torch.softmax(logits, 1).requires_grad_()
    loss_loop = lz.lovasz_softmax_flat(probs, labels, classes)
    grad_loop, = torch.autograd.grad(loss_loop, probs)
    with forced_accelerator_path():
        loss_batched = lz.lovasz_softmax_flat(probs, labels, classes)
    grad_batched, = torch.autograd.grad(loss_batched, probs)
    assert torch.allclose(loss_batched, loss_loop, atol=1e-6)
    assert torch.allclose(grad_batched, grad_loop, atol=1e-6)
