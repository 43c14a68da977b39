"""Which code path a device takes where the CPU and the GPU want different
ones.

A few functions have a path for the CPU (blocked for a core's cache, or a
Python loop whose small operations cost little there) and one for GPUs
(few large operations: each launch costs a GPU ~5-20 us of host time).
They ask :func:`accelerator_path`. ``tools/analysis_tools/count_ops.py``
counts a GPU's launches on the CPU under :func:`forced_accelerator_path`.
"""
import contextlib
from typing import Iterator, Optional

from torch import Tensor

_FORCED: Optional[bool] = None


def accelerator_path(tensor: Tensor) -> bool:
    """Whether to take the path written for GPUs: ``tensor`` is not on the
    CPU, unless :func:`forced_accelerator_path` says otherwise."""
    if _FORCED is not None:
        return _FORCED
    return tensor.device.type != 'cpu'


@contextlib.contextmanager
def forced_accelerator_path(on: bool = True) -> Iterator[None]:
    """Take (or refuse) the GPU path on every device inside the block."""
    global _FORCED
    before, _FORCED = _FORCED, bool(on)
    try:
        yield
    finally:
        _FORCED = before
