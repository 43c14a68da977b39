"""The vectorised rulebooks that GPUs take (issue 46: all kernel offsets at
once, two host syncs) give the pairs of the per-offset loops the CPU keeps,
offset by offset and in the same order, and the same output sites."""
import pytest
import torch

from projects.occ_common.models.sparse import rulebook as rb
from projects.occ_common.models.sparse.rulebook import delinearize


def _sites(num, shape, batch_size, seed):
    gen = torch.Generator().manual_seed(seed)
    volume = batch_size * shape[0] * shape[1] * shape[2]
    keys = torch.randperm(volume, generator=gen)[:num].sort().values
    return delinearize(keys, shape)


def _same(new, old):
    assert len(new.in_indices) == len(old.in_indices)
    for a, b in zip(new.in_indices, old.in_indices):
        assert torch.equal(a, b)
    for a, b in zip(new.out_indices, old.out_indices):
        assert torch.equal(a, b)
    assert torch.equal(new.out_coords, old.out_coords)
    assert new.center == old.center and new.out_shape == old.out_shape


@pytest.mark.parametrize('kernel, dilation', [((3, 3, 3), (1, 1, 1)),
                                              ((1, 3, 5), (1, 2, 1)),
                                              ((3, 1, 3), (2, 1, 2))])
def test_submanifold_pairs_equal_the_loop(kernel, dilation):
    coords = _sites(300, (6, 9, 11), 2, seed=sum(kernel))
    _same(rb._submanifold_rulebook_vectorised(coords, (6, 9, 11), kernel,
                                              dilation),
          rb._submanifold_rulebook_loop(coords, (6, 9, 11), kernel, dilation))


@pytest.mark.parametrize('kernel, stride, padding, dilation', [
    ((3, 3, 3), (2, 2, 2), (1, 1, 1), (1, 1, 1)),
    ((2, 2, 2), (2, 2, 2), (0, 0, 0), (1, 1, 1)),
    ((3, 1, 3), (1, 1, 2), (1, 0, 1), (1, 1, 2)),
])
def test_strided_pairs_equal_the_loop(kernel, stride, padding, dilation):
    coords = _sites(300, (6, 9, 11), 2, seed=sum(stride))
    _same(rb._strided_rulebook_vectorised(coords, (6, 9, 11), kernel,
                                          stride, padding, dilation),
          rb._strided_rulebook_loop(coords, (6, 9, 11), kernel, stride,
                                    padding, dilation))


def test_two_syncs_whatever_the_kernel():
    """A 3x3x3 submanifold rulebook: one ``nonzero`` and one read of the
    27 counts (the loop made 26 boolean-mask selections)."""
    from torch import nn

    from projects.occ_common.analysis.op_counting import OpCounter

    class _Build(nn.Module):

        def forward(self, coords):
            return rb._submanifold_rulebook_vectorised(
                coords, (6, 9, 11), (3, 3, 3), (1, 1, 1))

    coords = _sites(300, (6, 9, 11), 2, seed=0)
    counter = OpCounter(_Build())
    with counter:
        counter.model(coords)
    assert counter.totals()['syncs'] == 2


def test_the_device_picks_the_builder(monkeypatch):
    """CPU tensors take the loop, a forced accelerator path (what
    count_ops counts) the vectorised builder."""
    from projects.occ_common.utils.device_path import forced_accelerator_path
    calls = []
    monkeypatch.setattr(rb, '_submanifold_rulebook_vectorised',
                        lambda *a: calls.append('vectorised'))
    monkeypatch.setattr(rb, '_submanifold_rulebook_loop',
                        lambda *a: calls.append('loop'))
    coords = _sites(10, (6, 9, 11), 1, seed=0)
    rb.submanifold_rulebook(coords, (6, 9, 11), (3, 3, 3), (1, 1, 1))
    with forced_accelerator_path():
        rb.submanifold_rulebook(coords, (6, 9, 11), (3, 3, 3), (1, 1, 1))
    assert calls == ['loop', 'vectorised']
