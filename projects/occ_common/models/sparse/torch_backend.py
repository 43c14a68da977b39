"""Pure-PyTorch sparse convolution: gather, matmul and scatter per offset.

For every kernel offset ``k`` with pairs ``(i, o)`` the output gains
``f[i] @ W_k`` at row ``o`` (one ``index_add_``), i.e.

    y_o = b + sum_k sum_{(i, o) in R_k} W_k^T f_i,

so autograd differentiates it with respect to features, weight and bias
on any device. Weights use spconv's layout ``(C_out, k_z, k_y, k_x, C_in)``
and match its arithmetic, including spconv's 1x1 quirk (see
:func:`dense_1x1`), so a state dict trained with either backend gives the
same outputs in the other.
"""
from typing import Callable, Optional

import torch
from torch import Tensor

from ...utils.device_path import accelerator_path
from .backend import SparseConvLayer
from .rulebook import Rulebook, strided_rulebook, submanifold_rulebook
from .sparse_tensor import SparseTensor

BACKEND = 'torch'


def rulebook_conv(features: Tensor, weight: Tensor, bias: Optional[Tensor],
                  rulebook: Rulebook) -> Tensor:
    """Apply a sparse convolution given its rulebook.

    Args:
        features (Tensor): Input features. Shape (N, C_in).
        weight (Tensor): Kernel in spconv layout. Shape
            (C_out, k_z, k_y, k_x, C_in).
        bias (Tensor, optional): Shape (C_out,).
        rulebook (Rulebook): Pairs per kernel offset.

    Returns:
        Tensor: Output features. Shape (M, C_out), M = output sites.
    """
    c_out, c_in = weight.shape[0], weight.shape[-1]
    kernels = weight.reshape(c_out, -1, c_in).permute(1, 2, 0)  # K, Ci, Co
    if accelerator_path(features) and rulebook.num_pairs > 0:
        return _batched_conv(features, kernels, bias, rulebook)
    center = rulebook.center
    if center is not None:
        # The centre offset pairs every site with itself: one dense matmul
        # instead of a gather and a scatter over all rows.
        out = features @ kernels[center]
    else:
        out = features.new_zeros(rulebook.out_coords.shape[0], c_out)
    for k, (rows_in, rows_out) in enumerate(
            zip(rulebook.in_indices, rulebook.out_indices)):
        if k == center or rows_in.numel() == 0:
            continue
        # Under autocast the product is half / bfloat16 while the zeros of
        # a strided conv keep the features' dtype; index_add_ needs one.
        out.index_add_(
            0, rows_out,
            (features.index_select(0, rows_in) @ kernels[k]).to(out.dtype))
    if center is None and rulebook.num_pairs == 0:
        # No pair touched the weight: keep it (and the features) in the
        # graph so that backward through an empty batch still works.
        out = out + 0.0 * (weight.sum() + features.sum())
    if bias is not None:
        out = out + bias
    return out


def _batched_conv(features: Tensor, kernels: Tensor, bias: Optional[Tensor],
                  rulebook: Rulebook) -> Tensor:
    """:func:`rulebook_conv` in one gather, one ``bmm`` and one scatter.

    The GPU path: every non-centre offset's pairs padded to one block
    (:meth:`Rulebook.padded_pairs`, padding reads a zero row and writes a
    dropped row), instead of a gather, a matmul and a scatter per offset
    (78 launches a 3x3x3 layer). The sums are the same products added in
    another order: equal within float rounding
    (tests/occ_common/models/sparse/test_batched_conv.py).

    Args:
        features (Tensor): Shape (N, C_in).
        kernels (Tensor): Shape (K, C_in, C_out).
        bias (Tensor, optional): Shape (C_out,).
        rulebook (Rulebook): With at least one pair.

    Returns:
        Tensor: Shape (M, C_out).
    """
    offsets, in_pad, out_pad = rulebook.padded_pairs()
    num_out = rulebook.out_coords.shape[0]
    if rulebook.center is not None:
        out = features @ kernels[rulebook.center]
    else:
        out = features.new_zeros(num_out, kernels.shape[2])
    if offsets.numel():
        padded = torch.cat(
            [features, features.new_zeros(1, features.shape[1])])
        products = torch.bmm(padded[in_pad], kernels.index_select(0, offsets))
        out = torch.cat([out, out.new_zeros(1, out.shape[1])]).index_add(
            0, out_pad.flatten(),
            products.flatten(0, 1).to(out.dtype))[:num_out]
    if bias is not None:
        out = out + bias
    return out


def dense_1x1(features: Tensor, weight: Tensor,
              bias: Optional[Tensor]) -> Tensor:
    """Kernel-volume-1, stride-1 sparse conv, computed as spconv does.

    spconv 2.3 applies these layers as ``features @ weight.view(C_in,
    C_out)``, reading its ``(C_out, 1, 1, 1, C_in)`` weight in memory order
    rather than transposing it. We reproduce that so checkpoints keep their
    meaning across backends; for a freshly initialised layer it is just
    another parameterisation of the same linear map.

    Args:
        features (Tensor): Shape (N, C_in).
        weight (Tensor): Shape (C_out, 1, 1, 1, C_in).
        bias (Tensor, optional): Shape (C_out,).

    Returns:
        Tensor: Shape (N, C_out).
    """
    c_out, c_in = weight.shape[0], weight.shape[-1]
    out = features @ weight.reshape(c_in, c_out)
    if bias is not None:
        out = out + bias
    return out


def _reused_subm(layer: SparseConvLayer, x: SparseTensor,
                 rulebook: Rulebook) -> Rulebook:
    """Check that a cached rulebook fits this submanifold layer."""
    problems = []
    if not rulebook.subm:
        problems.append('it belongs to a strided conv')
    if rulebook.kernel_size != layer.kernel_size:
        problems.append(f'kernel_size {rulebook.kernel_size} != '
                        f'{layer.kernel_size}')
    if rulebook.dilation != layer.dilation:
        problems.append(f'dilation {rulebook.dilation} != {layer.dilation}')
    if rulebook.in_shape != x.spatial_shape:
        problems.append(f'spatial_shape {rulebook.in_shape} != '
                        f'{x.spatial_shape}')
    if rulebook.out_coords.shape[0] != x.num_voxels:
        problems.append(f'{rulebook.out_coords.shape[0]} sites != '
                        f'{x.num_voxels}')
    if problems:
        raise ValueError(f'submanifold conv cannot reuse indice_key '
                         f'{layer.indice_key!r}: ' + '; '.join(problems))
    return rulebook


def _inverse_rulebook(layer: SparseConvLayer, x: SparseTensor) -> Rulebook:
    """Look up and invert the rulebook of the paired strided conv."""
    cache_key = (BACKEND, layer.indice_key)
    if cache_key not in x.indice_dict:
        raise ValueError(
            f'inverse conv found no rulebook under indice_key '
            f'{layer.indice_key!r}; a strided SparseConv with that key must '
            f'run first on the torch backend (cached: '
            f'{sorted(str(k) for k in x.indice_dict)})')
    rulebook = x.indice_dict[cache_key]
    if rulebook.subm:
        raise ValueError(f'inverse conv needs the rulebook of a strided conv'
                         f', but indice_key {layer.indice_key!r} holds a '
                         'submanifold one')
    if rulebook.kernel_size != layer.kernel_size:
        raise ValueError(
            f'inverse conv has kernel_size {layer.kernel_size} but the conv '
            f'under indice_key {layer.indice_key!r} had '
            f'{rulebook.kernel_size}')
    if rulebook.out_shape != x.spatial_shape or \
            rulebook.out_coords.shape[0] != x.num_voxels:
        raise ValueError(
            f'inverse conv input ({x.num_voxels} sites, spatial_shape '
            f'{x.spatial_shape}) is not the output of the conv under '
            f'indice_key {layer.indice_key!r} ('
            f'{rulebook.out_coords.shape[0]} sites, {rulebook.out_shape})')
    return rulebook.inverted()


def _memoised(layer: SparseConvLayer, x: SparseTensor,
              build: Callable[[], Rulebook]) -> Rulebook:
    """``build()`` once per layer and input sites of a forward pass.

    While a graph is being built the rulebook is kept in ``x``'s
    :attr:`~SparseTensor.rulebook_memo`, keyed by the layer and the
    identity of the input's coordinate tensor (kept with it, so the key
    cannot be reused by another tensor); a checkpointed segment recomputed
    in the backward gets the same input tensor and finds it. Under
    ``no_grad`` nothing is recomputed, and nothing is kept.
    """
    if not torch.is_grad_enabled():
        return build()
    key = (id(layer), id(x.coords))
    entry = x.rulebook_memo.get(key)
    if entry is not None and entry[0] is x.coords:
        return entry[1]
    rulebook = build()
    x.rulebook_memo[key] = (x.coords, rulebook)
    return rulebook


def torch_sparse_conv(layer: SparseConvLayer,
                      x: SparseTensor) -> SparseTensor:
    """Run one sparse convolution layer with the torch backend.

    Args:
        layer (SparseConvLayer): Provides the geometry, ``weight`` and
            ``bias``.
        x (SparseTensor): Input with ``layer.in_channels`` channels.

    Returns:
        SparseTensor: Output; its rulebook cache gains this layer's entry
        under ``('torch', indice_key)`` when the layer has a key.
    """
    if layer.conv1x1:
        features = dense_1x1(x.features, layer.weight, layer.bias)
        return x.replace_feature(features)
    cache_key = (BACKEND, layer.indice_key)
    indice_dict = dict(x.indice_dict)
    if layer.inverse:
        rulebook = _inverse_rulebook(layer, x)
    elif layer.subm:
        cached = indice_dict.get(cache_key) if layer.indice_key else None
        if cached is not None:
            rulebook = _reused_subm(layer, x, cached)
        else:
            rulebook = _memoised(
                layer, x, lambda: submanifold_rulebook(
                    x.coords, x.spatial_shape, layer.kernel_size,
                    layer.dilation))
    else:
        if layer.indice_key is not None and cache_key in indice_dict:
            raise ValueError(
                f'strided conv indice_key {layer.indice_key!r} is already '
                'used in this sparse tensor; give each strided conv its own')
        rulebook = _memoised(
            layer, x, lambda: strided_rulebook(
                x.coords, x.spatial_shape, layer.kernel_size, layer.stride,
                layer.padding, layer.dilation))
    if layer.indice_key is not None and not layer.inverse:
        indice_dict[cache_key] = rulebook
    features = rulebook_conv(x.features, layer.weight, layer.bias, rulebook)
    return SparseTensor(
        features,
        rulebook.out_coords,
        rulebook.out_shape,
        x.batch_size,
        indice_dict=indice_dict,
        check=False,
        rulebook_memo=x.rulebook_memo)
