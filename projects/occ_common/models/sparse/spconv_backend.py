"""spconv 2.x backend: run a layer's own weight through spconv's kernels.

The layer keeps its ``weight`` and ``bias`` parameters (spconv's layout, so
state dicts are interchangeable); here we only wrap the
:class:`SparseTensor` into a ``spconv.pytorch.SparseConvTensor`` and call
the convolution routine that spconv's own modules call, passing our weight.
spconv's index pairs are cached in the sparse tensor's ``indice_dict``
under ``('spconv', indice_key)``, separate from the torch backend's.
"""
import functools
from typing import Dict, Hashable, Tuple

from .backend import SparseConvLayer, resolve_backend
from .sparse_tensor import SparseTensor
from .torch_backend import torch_sparse_conv

BACKEND = 'spconv'


@functools.lru_cache(maxsize=None)
def _make_convolution(geometry: Tuple, native: bool) -> object:
    """Build spconv's parameter-free convolution descriptor for a geometry.

    spconv's ``SparseConvolutionBase`` holds only the geometry and the
    algorithm; its ``_conv_forward`` takes weight and bias as arguments,
    which is what lets our layer own the parameters. Descriptors are cached
    here rather than on the layer so the layer stays deep-copyable.

    Args:
        geometry (tuple): ``layer.geometry``: in/out channels, kernel size,
            stride, padding, dilation, subm, inverse, indice key.
        native (bool): Use spconv's gather-GEMM-scatter algorithm, the only
            one with CPU kernels; otherwise spconv picks (implicit GEMM on
            CUDA).

    Returns:
        spconv.pytorch.conv.SparseConvolutionBase: The descriptor.
    """
    from spconv.core import ConvAlgo
    from spconv.pytorch.conv import SparseConvolutionBase
    (in_channels, out_channels, kernel_size, stride, padding, dilation, subm,
     inverse, indice_key) = geometry
    return SparseConvolutionBase(
        3,
        in_channels,
        out_channels,
        list(kernel_size),
        stride=list(stride),
        padding=list(padding),
        dilation=list(dilation),
        bias=False,
        subm=subm,
        inverse=inverse,
        indice_key=indice_key,
        algo=ConvAlgo.Native if native else None)


def spconv_sparse_conv(layer: SparseConvLayer,
                       x: SparseTensor) -> SparseTensor:
    """Run one sparse convolution layer with spconv.

    Args:
        layer (SparseConvLayer): Provides the geometry, ``weight`` and
            ``bias``.
        x (SparseTensor): Input with ``layer.in_channels`` channels.

    Returns:
        SparseTensor: Output, sites in spconv's order (not sorted).
    """
    from spconv.pytorch import SparseConvTensor
    resolve_backend(BACKEND, x.features)  # clear error if spconv is unusable
    if x.num_voxels == 0:
        # spconv 2.3's native kernels assert on empty inputs. Emptiness
        # propagates through every layer, so the torch backend can take over
        # consistently (its rulebooks, also for a later inverse conv).
        return torch_sparse_conv(layer, x)
    convolution = _make_convolution(layer.geometry,
                                    not x.features.is_cuda)
    own: Dict[Hashable, object] = {
        key: value
        for (backend, key), value in x.indice_dict.items()
        if backend == BACKEND
    }
    sp_input = SparseConvTensor(
        x.features.contiguous(),
        x.coords.contiguous(),
        list(x.spatial_shape),
        x.batch_size,
        indice_dict=own)
    # The bias is added here: spconv fuses it into the kernel in eval mode,
    # and its CPU kernels refuse a fused bias.
    sp_output = convolution._conv_forward(layer.training, sp_input,
                                          layer.weight, None)
    features = sp_output.features
    if layer.bias is not None:
        features = features + layer.bias
    indice_dict = dict(x.indice_dict)
    indice_dict.update({(BACKEND, key): value
                        for key, value in sp_output.indice_dict.items()})
    return SparseTensor(
        features,
        sp_output.indices,
        sp_output.spatial_shape,
        x.batch_size,
        indice_dict=indice_dict,
        check=False,
        rulebook_memo=x.rulebook_memo)
