"""Tests of the pure-PyTorch sparse convolution backend.

Values are checked by hand on 1D lines and against dense ``conv3d`` /
``conv_transpose3d`` on an 8x8x4 grid; gradients against the dense ops and
against finite differences (``torch.autograd.gradcheck``).
"""
import pytest
import torch
import torch.nn.functional as F
from torch.func import functional_call

from projects.occ_common.models.sparse import (SparseConv, SparseInverseConv,
                                               SparseTensor, SubMConv,
                                               delinearize, linearize,
                                               to_dense)


def _line(xs, values, width, batch=None):
    """One-channel sites on a (1, 1, width) line."""
    batch = batch or [0] * len(xs)
    coords = torch.tensor([[b, 0, 0, x] for b, x in zip(batch, xs)])
    feats = torch.tensor(values, dtype=torch.float32)[:, None]
    return SparseTensor(feats, coords, (1, 1, width), max(batch) + 1)


def _set_weight(layer, values, bias=None):
    """Write a 1-in, 1-out kernel along x."""
    with torch.no_grad():
        layer.weight.copy_(torch.tensor(values).view(layer.weight.shape))
        if bias is not None:
            layer.bias.fill_(bias)


def _random_sparse(num, shape=(4, 8, 8), batch_size=2, channels=2, seed=0,
                   dtype=torch.float32):
    """``num`` distinct random sites on a batched (Z, Y, X) grid."""
    gen = torch.Generator().manual_seed(seed)
    volume = batch_size * shape[0] * shape[1] * shape[2]
    keys = torch.randperm(volume, generator=gen)[:num]
    feats = torch.randn(num, channels, generator=gen, dtype=dtype)
    return SparseTensor(feats, delinearize(keys, shape), shape, batch_size)


def _dense_weight(layer):
    """Our (C_out, kz, ky, kx, C_in) kernel as conv3d's (C_out, C_in, ...)."""
    return layer.weight.permute(0, 4, 1, 2, 3)


def _gather(dense, coords):
    """Rows of a (B, C, Z, Y, X) volume at (batch, z, y, x). Shape (N, C)."""
    c = coords.long()
    return dense[c[:, 0], :, c[:, 1], c[:, 2], c[:, 3]]


def test_subm_conv_line_by_hand():
    """Kernel (1, 1, 3), w = [10, 100, 1000], bias 0.5; out_q = 0.5 +
    sum_k w_k f(q + k - 1) on b0:x0=1, b0:x1=2, b0:x3=3, b1:x1=4.

    b0:x0: 100 * 1 + 1000 * 2 + 0.5 = 2100.5
    b0:x1: 10 * 1 + 100 * 2 + 0.5 = 210.5
    b0:x3: 100 * 3 + 0.5 = 300.5 (x2 inactive, x4 outside)
    b1:x1: 100 * 4 + 0.5 = 400.5 (b0's sites are not neighbours)
    Gradient of sum(out) w.r.t. w_0 = f(x0) = 1 (one pair), w_1 = 1+2+3+4
    = 10, w_2 = f(x1) = 2; w.r.t. f(b0:x1) = w_1 + w_2 = 1100.
    """
    x = _line([0, 1, 3, 1], [1., 2., 3., 4.], 4, batch=[0, 0, 0, 1])
    x.features.requires_grad_(True)
    conv = SubMConv(1, 1, (1, 1, 3), backend='torch')
    _set_weight(conv, [10., 100., 1000.], bias=0.5)
    out = conv(x)
    assert out.features[:, 0].tolist() == [2100.5, 210.5, 300.5, 400.5]
    assert torch.equal(out.coords, x.coords)
    out.features.sum().backward()
    assert conv.weight.grad.flatten().tolist() == [1., 10., 2.]
    assert conv.bias.grad.tolist() == [4.]
    assert x.features.grad[:, 0].tolist() == [110., 1100., 100., 100.]


def test_strided_and_inverse_conv_line_by_hand():
    """Kernel = stride = 2 along x, w = [10, 100], no bias; x0=1, x1=2, x3=3.

    q0 = 10 * 1 + 100 * 2 = 210, q1 = 100 * 3 = 300 (x3 = 2 * 1 + 1).
    Inverse with v = [1, 2] sends q back through the same pairs:
    x0 = v0 * q0 = 210, x1 = v1 * q0 = 420, x3 = v1 * q1 = 600.
    """
    x = _line([0, 1, 3], [1., 2., 3.], 4)
    down = SparseConv(1, 1, (1, 1, 2), stride=(1, 1, 2), bias=False,
                      indice_key='d', backend='torch')
    _set_weight(down, [10., 100.])
    up = SparseInverseConv(1, 1, (1, 1, 2), 'd', bias=False, backend='torch')
    _set_weight(up, [1., 2.])
    coarse = down(x)
    assert coarse.spatial_shape == (1, 1, 2)
    assert coarse.coords[:, 3].tolist() == [0, 1]
    assert coarse.features[:, 0].tolist() == [210., 300.]
    fine = up(coarse)
    assert fine.spatial_shape == (1, 1, 4)
    assert torch.equal(fine.coords, x.coords)
    assert fine.features[:, 0].tolist() == [210., 420., 600.]


def test_conv1x1_follows_spconv_weight_reading():
    """A (C_out=3, 1, 1, 1, C_in=2) weight holding 0..5 is read, as spconv
    does, as the (C_in, C_out) matrix [[0, 1, 2], [3, 4, 5]]:
    f = [1, 10] -> [0 + 30, 1 + 40, 2 + 50] = [30, 41, 52]."""
    x = SparseTensor(torch.tensor([[1., 10.]]), torch.zeros(1, 4,
                                                            dtype=torch.int),
                     (1, 1, 1), 1)
    conv = SubMConv(2, 3, 1, bias=False, backend='torch')
    with torch.no_grad():
        conv.weight.copy_(torch.arange(6.).view(3, 1, 1, 1, 2))
    assert conv(x).features.tolist() == [[30., 41., 52.]]


@pytest.mark.parametrize('dilation', [1, 2])
def test_subm_conv_matches_dense_conv3d(dilation):
    """On active sites a submanifold conv equals a dense conv3d with
    padding = dilation * (k // 2), since inactive inputs are zero; so do
    the gradients of sum(out * g) w.r.t. features, weight and bias."""
    x = _random_sparse(24)
    x.features.requires_grad_(True)
    conv = SubMConv(2, 3, 3, dilation=dilation, backend='torch')
    out = conv(x)
    grad_out = torch.randn_like(out.features)
    (out.features * grad_out).sum().backward()
    sparse_grads = [t.grad.clone() for t in (x.features, conv.weight,
                                             conv.bias)]
    for t in (x.features, conv.weight, conv.bias):
        t.grad = None
    dense = F.conv3d(to_dense(x), _dense_weight(conv), conv.bias,
                     padding=dilation, dilation=dilation)
    expected = _gather(dense, x.coords)
    torch.testing.assert_close(out.features, expected)
    (expected * grad_out).sum().backward()
    for got, t in zip(sparse_grads, (x.features, conv.weight, conv.bias)):
        torch.testing.assert_close(got, t.grad)


def test_strided_conv_matches_dense_conv3d():
    """Without bias, a strided sparse conv densified equals conv3d: inactive
    outputs see only zeros. Gradients w.r.t. features and weight agree."""
    x = _random_sparse(24)
    x.features.requires_grad_(True)
    conv = SparseConv(2, 3, 3, stride=2, padding=1, bias=False,
                      backend='torch')
    out = to_dense(conv(x))
    dense = F.conv3d(to_dense(x), _dense_weight(conv), stride=2, padding=1)
    torch.testing.assert_close(out, dense)
    grad_out = torch.randn_like(out)
    grads = torch.autograd.grad((out * grad_out).sum(),
                                (x.features, conv.weight))
    expected = torch.autograd.grad((dense * grad_out).sum(),
                                   (x.features, conv.weight))
    for got, want in zip(grads, expected):
        torch.testing.assert_close(got, want)


def test_inverse_conv_matches_conv_transpose3d():
    """Inverse conv = conv_transpose3d (same stride, padding) at the fine
    active sites. Fine (4, 8, 8) -> coarse (2, 4, 4); transposing gives
    (2 - 1) * 2 - 2 + 3 = 3 levels, so output_padding 1 restores 4."""
    x = _random_sparse(24)
    down = SparseConv(2, 3, 3, stride=2, padding=1, indice_key='d1',
                      backend='torch')
    up = SparseInverseConv(3, 2, 3, 'd1', bias=False, backend='torch')
    coarse = down(x)
    coarse_feats = coarse.features.detach().requires_grad_(True)
    coarse = coarse.replace_feature(coarse_feats)
    out = up(coarse)
    assert torch.equal(out.coords, x.coords)
    dense = F.conv_transpose3d(
        to_dense(coarse), up.weight.permute(4, 0, 1, 2, 3), stride=2,
        padding=1, output_padding=1)
    expected = _gather(dense, x.coords)
    torch.testing.assert_close(out.features, expected)
    grad_out = torch.randn_like(expected)
    grads = torch.autograd.grad((out.features * grad_out).sum(),
                                (coarse_feats, up.weight))
    want = torch.autograd.grad((expected * grad_out).sum(),
                               (coarse_feats, up.weight))
    for got, ref in zip(grads, want):
        torch.testing.assert_close(got, ref)


def test_convs_run_under_autocast():
    """Under autocast (``--amp``; bfloat16 on CPU stands in for CUDA's
    float16) the per-offset products are low precision while a strided or
    inverse conv starts from zeros of the features' float32: the scatter
    must still work, give the float32 result to bfloat16 precision (8
    mantissa bits: relative error ~ 2^-8 per product, a few 1e-2 after
    summing 27 offsets) and backpropagate to float32 weights."""
    x = _random_sparse(24)
    subm = SubMConv(2, 3, 3, indice_key='s', backend='torch')
    down = SparseConv(3, 4, 3, stride=2, padding=1, indice_key='d',
                      backend='torch')
    up = SparseInverseConv(4, 2, 3, 'd', backend='torch')

    def chain():
        return up(down(subm(x))).features

    reference = chain()
    with torch.autocast('cpu', dtype=torch.bfloat16):
        low = chain()
    assert low.shape == reference.shape == (24, 2)
    torch.testing.assert_close(low.float(), reference, rtol=0.1, atol=0.05)
    low.float().sum().backward()
    for layer in (subm, down, up):
        assert layer.weight.grad.dtype == torch.float32
        assert bool(torch.isfinite(layer.weight.grad).all())
        assert torch.count_nonzero(layer.weight.grad) > 0


def test_gradcheck_finite_differences():
    """Analytic gradients of subm, strided and inverse convs match central
    finite differences in float64 on 10 sites of a 4x4x4 grid (gradcheck's
    fast mode: differences along random input directions, compared with
    the same projections of the analytic Jacobian)."""
    x = _random_sparse(10, shape=(4, 4, 4), batch_size=1, dtype=torch.float64)
    subm = SubMConv(2, 2, 3, indice_key='s', backend='torch').double()
    down = SparseConv(2, 2, 2, stride=2, indice_key='d',
                      backend='torch').double()
    up = SparseInverseConv(2, 2, 2, 'd', backend='torch').double()

    def chain(feats, w_subm, w_down, w_up):
        y = x.replace_feature(feats)
        for layer, weight in ((subm, w_subm), (down, w_down), (up, w_up)):
            y = functional_call(layer, {'weight': weight}, (y, ))
        return y.features

    inputs = tuple(
        t.detach().clone().requires_grad_(True)
        for t in (x.features, subm.weight, down.weight, up.weight))
    assert torch.autograd.gradcheck(
        chain, inputs, eps=1e-6, atol=1e-6, fast_mode=True)


def test_empty_input_keeps_graph():
    """No sites: outputs are (0, C_out); backward of sum(out) + sum(bias)
    works and gives weight gradient 0 and bias gradient 1 per channel (only
    the explicit sum(bias) term contributes)."""
    x = SparseTensor(torch.zeros(0, 2, requires_grad=True),
                     torch.zeros(0, 4, dtype=torch.int), (4, 8, 8), 2)
    subm = SubMConv(2, 3, 3, backend='torch')
    down = SparseConv(3, 4, 2, stride=2, indice_key='e', backend='torch')
    up = SparseInverseConv(4, 2, 2, 'e', backend='torch')
    coarse = down(subm(x))
    out = up(coarse)
    assert coarse.features.shape == (0, 4) and coarse.spatial_shape == (2, 4,
                                                                        4)
    assert out.features.shape == (0, 2)
    (out.features.sum() + up.bias.sum()).backward()
    assert torch.count_nonzero(down.weight.grad) == 0
    assert torch.count_nonzero(subm.weight.grad) == 0
    assert up.bias.grad.tolist() == [1., 1.]


def test_indice_key_reuses_and_guards_rulebooks():
    """Two subm convs with one key share one Rulebook object; a second
    strided conv with a used key, a mismatched kernel and an inverse conv
    without its strided partner all raise ValueError naming the key."""
    x = _random_sparse(12)
    first = SubMConv(2, 2, 3, indice_key='k', backend='torch')
    second = SubMConv(2, 2, 3, indice_key='k', backend='torch')
    y = first(x)
    z = second(y)
    assert z.indice_dict[('torch', 'k')] is y.indice_dict[('torch', 'k')]
    assert ('torch', 'k') not in x.indice_dict  # inputs are not mutated
    with pytest.raises(ValueError, match="reuse indice_key 'k'.*kernel_size"):
        SubMConv(2, 2, (1, 3, 3), indice_key='k', backend='torch')(y)
    down = SparseConv(2, 2, 2, stride=2, indice_key='d', backend='torch')
    coarse = down(y)
    with pytest.raises(ValueError, match="'d' is already used"):
        SparseConv(2, 2, 2, stride=2, indice_key='d', backend='torch')(coarse)
    with pytest.raises(ValueError, match="no rulebook under indice_key 'x'"):
        SparseInverseConv(2, 2, 2, 'x', backend='torch')(coarse)
    coarser = SparseConv(2, 2, 2, stride=2, indice_key='d2',
                         backend='torch')(coarse)
    with pytest.raises(ValueError, match='is not the output of the conv'):
        SparseInverseConv(2, 2, 2, 'd', backend='torch')(coarser)
    with pytest.raises(ValueError, match='kernel_size'):
        SparseInverseConv(2, 2, 3, 'd', backend='torch')(coarse)


def test_layer_argument_errors():
    """Bad channels, even subm kernels, unknown backends, inverse without a
    key or with a 1x1 kernel, wrong input types and widths raise."""
    with pytest.raises(ValueError, match='odd kernel_size'):
        SubMConv(2, 2, 2)
    with pytest.raises(ValueError, match='backend must be one of'):
        SubMConv(2, 2, 3, backend='cuda')
    with pytest.raises(ValueError, match='needs the indice_key'):
        SparseInverseConv(2, 2, 3, '')
    with pytest.raises(ValueError, match='kernel volume > 1'):
        SparseInverseConv(2, 2, 1, 'd')
    with pytest.raises(ValueError, match='positive channels'):
        SparseConv(0, 2, 3)
    with pytest.raises(ValueError, match='kernel_size must be an int or 3'):
        SparseConv(2, 2, (3, 3))
    conv = SubMConv(3, 2, 3, backend='torch')
    with pytest.raises(TypeError, match='expects a SparseTensor'):
        conv(torch.zeros(4, 3))
    with pytest.raises(ValueError, match='expects 3 input channels'):
        conv(_random_sparse(4))


def test_rulebook_keys_are_linear_order():
    """Strided outputs come sorted by key ((b * Z + z) * Y + y) * X + x."""
    x = _random_sparse(30)
    out = SparseConv(2, 2, 3, stride=2, padding=1, backend='torch')(x)
    keys = linearize(out.coords[:, 0], out.coords[:, 1:], out.spatial_shape)
    assert torch.all(keys[1:] > keys[:-1])


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs CUDA')
def test_torch_backend_cuda_matches_cpu():
    """The torch backend gives the same outputs and gradients on CUDA."""
    x = _random_sparse(40)
    conv = SubMConv(2, 3, 3, indice_key='s', backend='torch')
    down = SparseConv(3, 3, 2, stride=2, indice_key='d', backend='torch')
    up = SparseInverseConv(3, 2, 2, 'd', backend='torch')
    results = []
    for device in ('cpu', 'cuda'):
        layers = [m.to(device) for m in (conv, down, up)]
        for m in layers:
            m.zero_grad()
        y = SparseTensor(x.features.to(device), x.coords.to(device),
                         x.spatial_shape, x.batch_size)
        for m in layers:
            y = m(y)
        y.features.square().sum().backward()
        # Copies: .cpu() of a CPU tensor is the tensor itself, and the next
        # round's m.to('cuda') moves the parameters' gradients in place.
        results.append([y.features.detach().cpu().clone()] +
                       [m.weight.grad.cpu().clone() for m in layers])
    for cpu, cuda in zip(*results):
        torch.testing.assert_close(cpu, cuda, rtol=1e-4, atol=1e-4)


def test_state_dict_version_and_mmcv_layout():
    """State dicts carry version 2 (spconv 2.x layout, which mmdet3d's
    patched spconv loader expects). A version-less weight in mmcv-spconv's
    (kz, ky, kx, C_in, C_out) layout is permuted on load: entry
    [kz, ky, kx, i, o] lands at [o, kz, ky, kx, i]."""
    conv = SubMConv(2, 3, (1, 1, 3), backend='torch')
    assert conv.state_dict()._metadata['']['version'] == 2
    legacy = torch.arange(18.).view(1, 1, 3, 2, 3)
    conv.load_state_dict({'weight': legacy, 'bias': torch.zeros(3)})
    assert conv.weight[2, 0, 0, 1, 0].item() == legacy[0, 0, 1, 0, 2].item()
    assert torch.equal(conv.weight, legacy.permute(4, 0, 1, 2, 3))
    same = SubMConv(2, 3, (1, 1, 3), backend='torch')
    same.load_state_dict({'weight': conv.weight.detach(), 'bias': conv.bias})
    assert torch.equal(same.weight, conv.weight)
