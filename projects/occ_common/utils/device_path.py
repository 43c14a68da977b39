"""Which code path a device takes where the CPU and the GPU want different
ones.

A few functions have a path for the CPU (blocked for a core's cache, or a
Python loop whose small operations cost little there) and one for GPUs
(few large operations: each launch costs a GPU ~5-20 us of host time).
They ask :func:`accelerator_path`. ``tools/analysis_tools/count_ops.py``
counts a GPU's launches on the CPU under :func:`forced_accelerator_path`.

Code traced by ``torch.compile`` takes the GPU path on every device: the
CPU path's compactions (``nonzero``, boolean masks, ``unique``) have
data-dependent output sizes, each a graph break, while the GPU path keeps
every shape fixed by the input sizes (both paths give the same results;
the tests compare them).
"""
import contextlib
import os
from typing import Iterator, Optional

import torch
from torch import Tensor

#: Device memory assumed free when the GPU path is forced on a machine
#: without one (count_ops): a 24 GB GPU's, the smallest the paper configs
#: are meant for.
ASSUMED_FREE_BYTES = 24 * 2**30

_FORCED: Optional[bool] = None


def accelerator_path(tensor: Tensor) -> bool:
    """Whether to take the path written for GPUs: ``tensor`` is not on the
    CPU or the code is being compiled (``torch.compiler.is_compiling``),
    unless :func:`forced_accelerator_path` says otherwise."""
    if _FORCED is not None:
        return _FORCED
    return tensor.device.type != 'cpu' or torch.compiler.is_compiling()


@contextlib.contextmanager
def forced_accelerator_path(on: bool = True) -> Iterator[None]:
    """Take (or refuse) the GPU path on every device inside the block."""
    global _FORCED
    before, _FORCED = _FORCED, bool(on)
    try:
        yield
    finally:
        _FORCED = before


def chunk_items(tensor: Tensor, bytes_per_item: int, cpu_items: int,
                share: float = 0.25) -> int:
    """How many items a chunked loop should take at once.

    On the CPU, ``cpu_items`` (chunks sized for a core's cache). On the GPU
    path, as many as fit in ``share`` of the device's free memory at
    ``bytes_per_item`` each (the loop's temporaries per item), so that a
    paper-size lift runs in one or two chunks instead of a hundred
    launches' worth of small ones. Compiled code assumes
    :data:`ASSUMED_FREE_BYTES` instead of reading the free memory, which
    changes from call to call: a chunk count read at run time would be a
    graph break and a recompilation whenever it changed.

    Args:
        tensor (Tensor): Decides the device.
        bytes_per_item (int): Temporary bytes per item.
        cpu_items (int): The CPU's chunk.
        share (float): Of the free memory. Defaults to 0.25.

    Returns:
        int: At least 1.
    """
    if not accelerator_path(tensor):
        return cpu_items
    if tensor.is_cuda and not torch.compiler.is_compiling():
        free, _ = torch.cuda.mem_get_info(tensor.device)
    else:
        free = ASSUMED_FREE_BYTES
    return max(1, int(free * share) // max(1, int(bytes_per_item)))


#: Environment variable that makes :func:`check_index_range` read the
#: indices on the host on GPUs too, for a clear error while debugging.
HOST_CHECKS_ENV = 'OCC_HOST_CHECKS'


def check_index_range(index: Tensor, low: int, high: int,
                      what: str) -> None:
    """Raise unless ``low <= index < high`` everywhere.

    A model's own indices (voxel rows it computed) are checked as an
    invariant. On the CPU the range is read and a violation is a
    ``ValueError`` naming it. On the GPU path, reading it would make the
    host wait for the device at every call, so the check is queued on the
    device instead (``torch._assert_async``: a violation stops the process
    with a device-side assert, as an out-of-range index in the kernel
    itself would) unless the environment sets ``OCC_HOST_CHECKS=1``.

    Args:
        index (Tensor): Integer indices. Any shape.
        low (int): Smallest allowed value.
        high (int): One past the largest allowed value.
        what (str): What the indices are, for the message.

    Raises:
        ValueError: A value outside ``[low, high)`` (host check).
    """
    if index.numel() == 0:
        return
    if accelerator_path(index) and os.environ.get(HOST_CHECKS_ENV) != '1':
        torch._assert_async(((index >= low) & (index < high)).all())
        return
    lo, hi = int(index.min()), int(index.max())
    if lo < low or hi >= high:
        raise ValueError(f'{what} must lie in [{low}, {high}), got values '
                         f'in [{lo}, {hi}]')
