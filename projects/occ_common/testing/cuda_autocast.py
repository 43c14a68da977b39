"""CUDA's autocast op lists, emulated on the CPU for the tests.

``torch.autocast('cpu', dtype)`` lowers the same matrix products and
convolutions as CUDA's autocast, but its other lists differ: the CPU runs
``softmax``, ``log``, ``sum``, ``layer_norm``... in the low-precision dtype
where CUDA runs them in float32, makes ``grid_sample`` float32 where CUDA
takes the widest input, and computes ``binary_cross_entropy`` where CUDA
refuses it. :func:`cuda_like_autocast` is CPU autocast plus a
``TorchFunctionMode`` that applies CUDA's rules to those functions (the
lists of the PyTorch AMP documentation, "CUDA Ops that can autocast to
float32", "CUDA Ops that promote to the widest input type" and the
``binary_cross_entropy`` refusal), so a CPU test sees what a GPU run
would. It matches functions by name at the Python level: an op reached
only inside another op's C++ kernel is not seen (autocast itself still
lowers it as the CPU does).
"""
import contextlib
from typing import Iterator

import torch
from torch.overrides import TorchFunctionMode

from ..utils.precision import autocast_disabled, to_float32

#: CUDA autocast runs these in float32.
CUDA_FP32_OPS = frozenset({
    '__pow__', '__rdiv__', '__rpow__', '__rtruediv__', 'acos', 'asin',
    'binary_cross_entropy_with_logits', 'cosh', 'cosine_embedding_loss',
    'cdist', 'cosine_similarity', 'cross_entropy', 'cumprod', 'cumsum',
    'dist', 'erfinv', 'exp', 'expm1', 'group_norm', 'hinge_embedding_loss',
    'kl_div', 'l1_loss', 'layer_norm', 'log', 'log_softmax', 'log10',
    'log1p', 'log2', 'margin_ranking_loss', 'mse_loss',
    'multilabel_margin_loss', 'multi_margin_loss', 'nll_loss', 'norm',
    'normalize', 'pdist', 'poisson_nll_loss', 'pow', 'prod', 'reciprocal',
    'rsqrt', 'sinh', 'smooth_l1_loss', 'soft_margin_loss', 'softmax',
    'softmin', 'softplus', 'sum', 'renorm', 'tan', 'triplet_margin_loss'
})
#: CUDA autocast runs these in the widest floating dtype of the inputs.
CUDA_PROMOTE_OPS = frozenset({
    'addcdiv', 'addcmul', 'atan2', 'bilinear', 'cross', 'dot',
    'grid_sample', 'index_put', 'scatter_add', 'tensordot'
})
#: CUDA autocast raises for these.
CUDA_REFUSED_OPS = frozenset({'binary_cross_entropy'})


def _tensors(value) -> list:
    if isinstance(value, torch.Tensor):
        return [value]
    if isinstance(value, (list, tuple)):
        return [t for v in value for t in _tensors(v)]
    if isinstance(value, dict):
        return [t for v in value.values() for t in _tensors(v)]
    return []


def _to_dtype(value, dtype: torch.dtype):
    if isinstance(value, torch.Tensor):
        return value.to(dtype) if value.is_floating_point() else value
    if isinstance(value, (list, tuple)):
        cast = [_to_dtype(v, dtype) for v in value]
        return type(value)(cast) if isinstance(value, list) else tuple(cast)
    if isinstance(value, dict):
        return {k: _to_dtype(v, dtype) for k, v in value.items()}
    return value


class CudaAutocastRules(TorchFunctionMode):
    """While CPU autocast is on, CUDA's float32, promote and refusal rules
    for the functions of :data:`CUDA_FP32_OPS`, :data:`CUDA_PROMOTE_OPS`
    and :data:`CUDA_REFUSED_OPS`."""

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        name = getattr(func, '__name__', '')
        if not torch.is_autocast_enabled('cpu'):
            return func(*args, **kwargs)
        if name in CUDA_REFUSED_OPS:
            raise RuntimeError(
                f'{name} is unsafe to autocast: CUDA autocast refuses it '
                '(emulated by projects/occ_common/testing/cuda_autocast.py)')
        if name in CUDA_FP32_OPS:
            with autocast_disabled():
                return func(*to_float32(args), **to_float32(kwargs))
        if name in CUDA_PROMOTE_OPS:
            floats = [
                t.dtype for t in _tensors((args, kwargs))
                if t.is_floating_point()
            ]
            widest = floats[0] if floats else None
            for dtype in floats[1:]:
                widest = torch.promote_types(widest, dtype)
            with autocast_disabled():
                if widest is None:
                    return func(*args, **kwargs)
                return func(*_to_dtype(args, widest),
                            **_to_dtype(kwargs, widest))
        return func(*args, **kwargs)


@contextlib.contextmanager
def cuda_like_autocast(dtype: torch.dtype) -> Iterator[None]:
    """CPU autocast to ``dtype`` with CUDA's op rules
    (:class:`CudaAutocastRules`)."""
    with torch.autocast('cpu', dtype=dtype), CudaAutocastRules():
        yield
