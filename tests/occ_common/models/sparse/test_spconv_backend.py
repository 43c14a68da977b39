"""Parity of the torch backend with spconv (same weights, same input).

spconv 2.3's CPU wheel runs the forward of its convolutions on CPU (its
backward needs CUDA), so the forward parity runs here on CPU. The tests
skip only when spconv is missing or cannot run a convolution on CPU.
"""
import pytest
import torch

from projects.occ_common.models.sparse import (SparseConv, SparseInverseConv,
                                               SparseTensor, SubMConv,
                                               delinearize, linearize,
                                               resolve_backend,
                                               spconv_available,
                                               spconv_supports_cuda)


def _spconv_runs_on_cpu():
    """Whether a tiny spconv submanifold conv runs on CPU."""
    if not spconv_available():
        return False
    try:
        import spconv.pytorch as spconv
        x = spconv.SparseConvTensor(
            torch.ones(1, 1), torch.zeros(1, 4, dtype=torch.int32),
            [1, 1, 1], 1)
        spconv.SubMConv3d(1, 1, 3)(x)
    except Exception:  # any failure means the CPU path is unusable
        return False
    return True


needs_spconv_cpu = pytest.mark.skipif(
    not _spconv_runs_on_cpu(), reason='spconv cannot run on CPU here')


@pytest.fixture(autouse=True)
def single_thread():
    """Run with one torch thread: spconv 2.3.8's CPU path intermittently
    returns wrong strided-conv features with two threads (observed through
    spconv's own SparseConv3d, 28 of 40 calls at 15k voxels)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _random_sparse(num, shape=(4, 8, 8), batch_size=2, channels=3, seed=0):
    """``num`` distinct random sites on a batched (Z, Y, X) grid."""
    gen = torch.Generator().manual_seed(seed)
    volume = batch_size * shape[0] * shape[1] * shape[2]
    keys = torch.randperm(volume, generator=gen)[:num]
    feats = torch.randn(num, channels, generator=gen)
    return SparseTensor(feats, delinearize(keys, shape), shape, batch_size)


def _sorted(x):
    """Coords and features ordered by linear key, since spconv does not
    sort its strided outputs."""
    keys = linearize(x.coords[:, 0], x.coords[:, 1:], x.spatial_shape)
    order = torch.argsort(keys)
    return x.coords[order], x.features[order]


def _pair(cls, *args, training=True, **kwargs):
    """The same layer on both backends, sharing one state dict (with a
    bias, which spconv treats differently in training and eval)."""
    ours = cls(*args, backend='torch', **kwargs).train(training)
    theirs = cls(*args, backend='spconv', **kwargs).train(training)
    theirs.load_state_dict(ours.state_dict())
    return ours, theirs


def _assert_same(ours, theirs):
    """Same grid, same sites, features equal to float tolerance."""
    assert ours.spatial_shape == theirs.spatial_shape
    coords_a, feats_a = _sorted(ours)
    coords_b, feats_b = _sorted(theirs)
    assert torch.equal(coords_a, coords_b)
    torch.testing.assert_close(feats_a, feats_b, rtol=1e-5, atol=1e-5)


@needs_spconv_cpu
@pytest.mark.parametrize('training', [True, False])
@pytest.mark.parametrize('kwargs', [
    dict(kernel_size=3),
    dict(kernel_size=(3, 1, 3), dilation=2),
    dict(kernel_size=(1, 3, 5)),
    dict(kernel_size=1),
])
def test_subm_parity(kwargs, training):
    """Submanifold conv: 40 sites, two samples, 3 -> 5 channels, in
    training and eval mode."""
    x = _random_sparse(40)
    ours, theirs = _pair(SubMConv, 3, 5, training=training, **kwargs)
    _assert_same(ours(x), theirs(x))


@needs_spconv_cpu
@pytest.mark.parametrize('training', [True, False])
@pytest.mark.parametrize('kwargs', [
    dict(kernel_size=3, stride=2, padding=1),
    dict(kernel_size=2, stride=2),
    dict(kernel_size=(3, 3, 3), stride=(1, 2, 2), padding=(0, 1, 1)),
    dict(kernel_size=3, stride=1, padding=1, dilation=2),
    dict(kernel_size=1),
])
def test_strided_parity(kwargs, training):
    """Regular sparse conv, including the dilation of the active set, in
    training and eval mode."""
    x = _random_sparse(40)
    ours, theirs = _pair(SparseConv, 3, 5, training=training, **kwargs)
    _assert_same(ours(x), theirs(x))


@needs_spconv_cpu
@pytest.mark.parametrize('kwargs', [
    dict(kernel_size=3, stride=2, padding=1),
    dict(kernel_size=2, stride=2),
])
@pytest.mark.parametrize('training', [True, False])
def test_inverse_parity(kwargs, training):
    """Down with a strided conv, back up with the inverse conv: both
    backends restore the 40 input sites with equal features."""
    x = _random_sparse(40)
    down_a, down_b = _pair(SparseConv, 3, 4, indice_key='down',
                           training=training, **kwargs)
    up_a, up_b = _pair(SparseInverseConv, 4, 6, kwargs['kernel_size'],
                       'down', training=training)
    out_a, out_b = up_a(down_a(x)), up_b(down_b(x))
    _assert_same(out_a, out_b)
    assert torch.equal(_sorted(out_a)[0], _sorted(x)[0])


@needs_spconv_cpu
def test_stacked_layers_reuse_spconv_indices():
    """A subm pair sharing a key, a strided conv and its inverse on spconv
    equal the torch backend; spconv's pairs are cached under
    ('spconv', key), apart from the torch rulebooks."""
    x = _random_sparse(40)
    layers = [
        _pair(SubMConv, 3, 4, 3, indice_key='s0'),
        _pair(SubMConv, 4, 4, 3, indice_key='s0'),
        _pair(SparseConv, 4, 4, 3, stride=2, padding=1, indice_key='d1'),
        _pair(SparseInverseConv, 4, 2, 3, 'd1'),
    ]
    out_a, out_b = x, x
    for ours, theirs in layers:
        out_a, out_b = ours(out_a), theirs(out_b)
    _assert_same(out_a, out_b)
    assert {k[0] for k in out_b.indice_dict} == {'spconv'}
    assert {k[0] for k in out_a.indice_dict} == {'torch'}


@needs_spconv_cpu
def test_state_dicts_interchange_with_spconv_modules():
    """spconv's own SubMConv3d / SparseConv3d / SparseInverseConv3d state
    dicts load strictly into our layers (and back) and give equal
    outputs: same keys, same (C_out, kz, ky, kx, C_in) weight layout."""
    import spconv.pytorch as spconv
    x = _random_sparse(40)
    sp_x = spconv.SparseConvTensor(x.features, x.coords, list(x.spatial_shape),
                                   x.batch_size)
    sp_subm = spconv.SubMConv3d(3, 4, 3, indice_key='s')
    sp_down = spconv.SparseConv3d(4, 5, 3, stride=2, padding=1,
                                  indice_key='d')
    sp_up = spconv.SparseInverseConv3d(5, 2, 3, indice_key='d')
    subm = SubMConv(3, 4, 3, indice_key='s', backend='torch')
    down = SparseConv(4, 5, 3, stride=2, padding=1, indice_key='d',
                      backend='torch')
    up = SparseInverseConv(5, 2, 3, 'd', backend='torch')
    for ours, theirs in ((subm, sp_subm), (down, sp_down), (up, sp_up)):
        ours.load_state_dict(theirs.state_dict(), strict=True)
        assert set(ours.state_dict()) == set(theirs.state_dict())
        theirs.load_state_dict(ours.state_dict(), strict=True)
    sp_mid = sp_down(sp_subm(sp_x))
    mid = down(subm(x))
    _assert_same(
        mid,
        SparseTensor(sp_mid.features, sp_mid.indices, sp_mid.spatial_shape,
                     x.batch_size))
    sp_out = sp_up(sp_mid)
    out = up(mid)
    _assert_same(
        out,
        SparseTensor(sp_out.features, sp_out.indices, sp_out.spatial_shape,
                     x.batch_size))


@needs_spconv_cpu
def test_spconv_backend_empty_input():
    """spconv on an empty tensor gives (0, C_out) like the torch backend."""
    x = SparseTensor(torch.zeros(0, 3), torch.zeros(0, 4, dtype=torch.int),
                     (4, 8, 8), 1)
    for cls, kwargs in ((SubMConv, dict(kernel_size=3)),
                        (SparseConv, dict(kernel_size=2, stride=2))):
        ours, theirs = _pair(cls, 3, 5, **kwargs)
        a, b = ours(x), theirs(x)
        assert a.features.shape == b.features.shape == (0, 5)
        assert a.spatial_shape == b.spatial_shape


def test_auto_backend_resolution():
    """'auto' picks torch for CPU tensors; unknown names are rejected."""
    cpu = torch.zeros(2, 3)
    assert resolve_backend('auto', cpu) == 'torch'
    assert resolve_backend('torch', cpu) == 'torch'
    with pytest.raises(ValueError, match="one of \\('auto', 'spconv'"):
        resolve_backend('minkowski', cpu)
    if spconv_available():
        assert resolve_backend('spconv', cpu) == 'spconv'
    else:
        with pytest.raises(ImportError, match='spconv cannot be imported'):
            resolve_backend('spconv', cpu)


@pytest.mark.skipif(
    not (torch.cuda.is_available() and spconv_supports_cuda()),
    reason='needs CUDA and a CUDA build of spconv')
def test_cuda_auto_uses_spconv_and_matches_torch_with_gradients():
    """On CUDA 'auto' runs spconv; forward and weight/feature gradients
    equal the torch backend's."""
    x = _random_sparse(40)
    x = SparseTensor(x.features.cuda().requires_grad_(True), x.coords.cuda(),
                     x.spatial_shape, x.batch_size)
    assert resolve_backend('auto', x.features) == 'spconv'
    results = []
    for backend in ('torch', 'auto'):
        torch.manual_seed(0)
        subm = SubMConv(3, 4, 3, backend=backend).cuda()
        down = SparseConv(4, 4, 3, stride=2, padding=1, backend=backend).cuda()
        out = down(subm(x))
        coords, feats = _sorted(out)
        grads = torch.autograd.grad(
            (feats * torch.arange(feats.numel(), device='cuda').view_as(feats)
             ).sum(), (x.features, subm.weight, down.weight))
        results.append((coords, feats) + grads)
    for a, b in zip(*results):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-4)
