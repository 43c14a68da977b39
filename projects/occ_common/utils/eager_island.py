"""Eager islands in compiled models: code whose sizes depend on the data.

Some steps produce tensors whose size only the data decides: the LiDAR
points inside a volume, the (camera, point) pairs a camera sees, a sparse
encoder's voxels and rulebook pairs. Under ``torch.compile`` each such
operator is a graph break, and the graph Dynamo starts after it takes the
data-dependent tensors as new inputs of fixed size: the next sample, with
another count, compiles that graph again (and again for each function on
the way). :func:`eager_island` instead runs such a step eagerly, as one
break, and marks the data-dependent dimension of what it returns dynamic,
so the compiled code after it takes any size without recompiling.
Without ``torch.compile`` it changes nothing.
"""
import functools
from typing import Callable, Optional

import torch


def _mark(value, dim: int):
    if isinstance(value, torch.Tensor):
        if value.dim() > dim:
            torch._dynamo.maybe_mark_dynamic(value, dim)
    elif isinstance(value, (list, tuple)):
        for item in value:
            _mark(item, dim)
    return value


def eager_island(fn: Optional[Callable] = None, *,
                 dynamic_dim: Optional[int] = 0) -> Callable:
    """Run ``fn`` eagerly inside compiled code, its outputs' size dynamic.

    Use as ``@eager_island`` or ``@eager_island(dynamic_dim=None)``.

    Args:
        fn (Callable): A function returning tensors (or lists / tuples of
            them).
        dynamic_dim (int, optional): The dimension of every returned
            tensor that the data sizes (marked with
            ``torch._dynamo.maybe_mark_dynamic``); None marks nothing
            (outputs of fixed size). Defaults to 0.

    Returns:
        Callable: ``fn``, skipped by Dynamo.
    """
    if fn is None:
        return functools.partial(eager_island, dynamic_dim=dynamic_dim)

    @torch.compiler.disable
    @functools.wraps(fn)
    def island(*args, **kwargs):
        out = fn(*args, **kwargs)
        return out if dynamic_dim is None else _mark(out, dynamic_dim)

    return island
