"""Rulebooks are built once per forward, also where a checkpointed segment
is recomputed in the backward (issue 46).

The encoder is test_spvcnn_encoder.py's tiny one (8x8x4 grid of 1 m
voxels; stem, a stride-2 stage and a stride-1 stage, one block each).
"""
import pytest
import torch

from projects.occ_common.models.sparse import (SPVCNNEncoder, SubMConv,
                                               torch_backend)
from projects.occ_common.models.sparse.sparse_tensor import SparseTensor


def _encoder(with_cp):
    torch.manual_seed(0)
    return SPVCNNEncoder(
        in_channels=4, voxel_size=(1.0, 1.0, 1.0),
        point_cloud_range=(0.0, 0.0, 0.0, 8.0, 8.0, 4.0), base_channels=4,
        stage_channels=(8, 8), stage_strides=(2, 1), bev_shape=(4, 4),
        out_channels=6, backend='torch', with_cp=with_cp)


def _clouds():
    gen = torch.Generator().manual_seed(3)
    scale = torch.tensor([8.0, 8.0, 4.0, 1.0])
    return [torch.rand(40, 4, generator=gen) * scale,
            torch.rand(25, 4, generator=gen) * scale]


@pytest.fixture
def builds(monkeypatch):
    """Counts the torch backend's rulebook builds."""
    counts = dict(subm=0, strided=0)

    def counting(name, build):
        def wrapped(*args, **kwargs):
            counts[name] += 1
            return build(*args, **kwargs)
        return wrapped

    monkeypatch.setattr(torch_backend, 'submanifold_rulebook',
                        counting('subm', torch_backend.submanifold_rulebook))
    monkeypatch.setattr(torch_backend, 'strided_rulebook',
                        counting('strided', torch_backend.strided_rulebook))
    return counts


def _step(with_cp, builds):
    """Forward and backward; the builds, the BEV and the gradients."""
    enc = _encoder(with_cp).train()
    bev = enc(_clouds())['bev']
    forward = dict(builds)
    weights = torch.linspace(-1, 1, bev.numel()).view_as(bev)
    (bev * weights).sum().backward()
    grads = {n: p.grad.clone() for n, p in enc.named_parameters()}
    after = dict(builds)
    builds.update(subm=0, strided=0)
    return forward, after, bev.detach(), grads


def test_recomputation_builds_no_rulebook(builds, code_path):
    """With with_cp the backward reruns the stem and both stages; the
    builds after the backward equal those of the forward and those of the
    same step without recomputation (before the memo the recomputation
    built every rulebook of the stages a second time), and the BEV and
    every gradient equal the plain step's."""
    plain_fwd, plain_all, plain_bev, plain_grads = _step(False, builds)
    cp_fwd, cp_all, cp_bev, cp_grads = _step(True, builds)
    assert plain_fwd == plain_all == cp_fwd == cp_all
    assert plain_fwd['strided'] == 1 and plain_fwd['subm'] >= 2
    torch.testing.assert_close(cp_bev, plain_bev, rtol=0, atol=0)
    for name, grad in plain_grads.items():
        torch.testing.assert_close(cp_grads[name], grad, rtol=1e-6,
                                   atol=1e-7, msg=name)


def test_memo_keys_are_layer_and_input_sites(builds):
    """One layer on the same tensor twice builds once; on other sites (an
    equal copy of the coordinates is another tensor) once more; under
    no_grad nothing is kept."""
    conv = SubMConv(2, 3, 3, backend='torch')
    coords = torch.tensor([[0, 0, 0, 0], [0, 0, 0, 1], [0, 1, 1, 1]])
    x = SparseTensor(torch.randn(3, 2), coords, (2, 2, 2), 1)
    conv(x)
    conv(x)
    assert builds['subm'] == 1 and len(x.rulebook_memo) == 1
    other = SparseTensor(torch.randn(3, 2), coords.clone(), (2, 2, 2), 1,
                         rulebook_memo=x.rulebook_memo)
    conv(other)
    assert builds['subm'] == 2 and len(x.rulebook_memo) == 2
    fresh = SparseTensor(torch.randn(3, 2), coords, (2, 2, 2), 1)
    with torch.no_grad():
        conv(fresh)
        conv(fresh)
    assert builds['subm'] == 4 and fresh.rulebook_memo == {}
