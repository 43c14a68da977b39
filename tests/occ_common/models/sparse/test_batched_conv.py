"""The torch backend's batched sparse convolution (the GPU path: one
gather, one bmm, one scatter a layer) against the per-offset loop the CPU
keeps: values and the gradients of features, weight and bias, for
submanifold, strided and inverse layers."""
import pytest
import torch

from projects.occ_common.models.sparse import (SparseConv, SparseInverseConv,
                                               SparseTensor, SubMConv,
                                               delinearize)
from projects.occ_common.utils.device_path import forced_accelerator_path


def _input(seed=0, num=300, channels=4):
    gen = torch.Generator().manual_seed(seed)
    shape, batch = (6, 9, 11), 2
    keys = torch.randperm(batch * 6 * 9 * 11, generator=gen)[:num]
    feats = torch.randn(num, channels, generator=gen).requires_grad_()
    return SparseTensor(feats, delinearize(keys.sort().values, shape), shape,
                        batch)


def _run(layers, x, accelerator):
    with forced_accelerator_path(accelerator):
        y = x
        for layer in layers:
            y = layer(y)
    params = [x.features] + [p for m in layers for p in m.parameters()]
    grad_out = torch.randn(y.features.shape,
                           generator=torch.Generator().manual_seed(1))
    return y.features, torch.autograd.grad(y.features, params, grad_out)


@pytest.mark.parametrize('build', [
    lambda: [SubMConv(4, 5, 3, indice_key='s', backend='torch')],
    lambda: [SubMConv(4, 5, (1, 3, 5), dilation=(1, 2, 1),
                      backend='torch')],
    lambda: [SparseConv(4, 5, 3, stride=2, padding=1, backend='torch')],
    lambda: [SparseConv(4, 5, 2, stride=2, indice_key='d', backend='torch'),
             SparseInverseConv(5, 3, 2, indice_key='d', backend='torch')],
], ids=['subm-3', 'subm-dilated', 'strided', 'strided+inverse'])
def test_batched_matches_the_offset_loop(build):
    torch.manual_seed(0)
    layers = build()
    x = _input()
    loop_out, loop_grads = _run(layers, x, accelerator=False)
    batch_out, batch_grads = _run(layers, x, accelerator=True)
    assert torch.allclose(batch_out, loop_out, atol=1e-5)
    for got, want in zip(batch_grads, loop_grads):
        assert torch.allclose(got, want, atol=1e-5)


def test_padded_pairs_by_hand():
    """Sites x = 0, 1, 3 on a (1, 1, 4) line, kernel (1, 1, 3): offset 0
    (x - 1) pairs 1 <- 0; offset 2 (x + 1) pairs 0 <- 1; the centre
    (offset 1) is left to the dense matmul. Padded to 1 column; nothing
    to pad, so no row N = 3 or M = 3 appears."""
    from projects.occ_common.models.sparse.rulebook import submanifold_rulebook
    coords = torch.tensor([[0, 0, 0, 0], [0, 0, 0, 1], [0, 0, 0, 3]])
    rulebook = submanifold_rulebook(coords, (1, 1, 4), (1, 1, 3), (1, 1, 1))
    offsets, in_pad, out_pad = rulebook.padded_pairs()
    assert offsets.tolist() == [0, 2]
    assert in_pad.tolist() == [[0], [1]]
    assert out_pad.tolist() == [[1], [0]]
