"""The toy model's loss: cross-entropy that deterministic mode allows."""
import math

import pytest
import torch
from torch import nn

from projects.occ_common.testing.toy_model import _cross_entropy


def test_equals_torch_cross_entropy_in_value_and_gradient():
    """Equal logits give log(1/3) per voxel: loss ln 3 = 1.0986123; random
    logits: the same value and gradient as ``F.cross_entropy``."""
    flat = _cross_entropy(torch.zeros(1, 3, 2, 2, 2),
                          torch.zeros(1, 2, 2, 2, dtype=torch.long))
    assert flat.item() == pytest.approx(math.log(3), abs=1e-7)

    gen = torch.Generator().manual_seed(0)
    logits = torch.randn(2, 3, 4, 3, 2, generator=gen, requires_grad=True)
    gt = torch.randint(0, 3, (2, 4, 3, 2), generator=gen)
    ours = _cross_entropy(logits, gt)
    (grad_ours, ) = torch.autograd.grad(ours, logits)
    theirs = nn.functional.cross_entropy(logits, gt)
    (grad_theirs, ) = torch.autograd.grad(theirs, logits)
    torch.testing.assert_close(ours, theirs)
    torch.testing.assert_close(grad_ours, grad_theirs)


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs CUDA')
def test_runs_on_cuda_in_deterministic_mode_where_nll_loss_refuses():
    """The resume tests train with ``randomness.deterministic=True``: on
    CUDA ``F.cross_entropy`` of 5-D logits raises there (``nll_loss2d``
    has no deterministic kernel); the toy loss runs and keeps its value."""
    logits = torch.randn(1, 3, 4, 4, 2, device='cuda', requires_grad=True)
    gt = torch.randint(0, 3, (1, 4, 4, 2), device='cuda')
    expected = nn.functional.cross_entropy(logits, gt).item()
    torch.use_deterministic_algorithms(True)
    try:
        with pytest.raises(RuntimeError, match='deterministic'):
            nn.functional.cross_entropy(logits, gt).backward()
        loss = _cross_entropy(logits, gt)
        loss.backward()
    finally:
        torch.use_deterministic_algorithms(False)
    assert loss.item() == pytest.approx(expected, rel=1e-6)
    assert torch.isfinite(logits.grad).all()
