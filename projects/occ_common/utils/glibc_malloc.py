"""glibc malloc settings that keep freed memory in the process.

Shared by :class:`~projects.occ_common.engine.hooks.CPUMallocTuningHook`
(training and testing through a Runner) and the benchmark tools
(``--keep-freed-memory``); see the hook's module for why and what it
measured. A leaf module: ctypes only.
"""
import ctypes
import ctypes.util
from typing import Optional

#: ``mallopt`` parameters (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
#: ``mallopt`` takes an ``int``.
INT_MAX = 2**31 - 1
#: Defaults: allocations up to 1 GiB come from the heap, and up to 2 GiB
#: freed at its top stay in the process.
MMAP_THRESHOLD = 1 << 30
TRIM_THRESHOLD = INT_MAX


def glibc() -> Optional[ctypes.CDLL]:
    """The C library if it is glibc (the one with ``mallopt``), else None."""
    name = ctypes.util.find_library('c')
    if name is None:
        return None
    try:
        libc = ctypes.CDLL(name)
    except OSError:
        return None
    if not hasattr(libc, 'mallopt') or not hasattr(libc,
                                                   'gnu_get_libc_version'):
        return None
    return libc


def checked_threshold(name: str, value: int) -> int:
    """``value`` as an int, refused unless ``mallopt`` can take it."""
    value = int(value)
    if not 0 <= value <= INT_MAX:
        raise ValueError(f'{name} must be in [0, {INT_MAX}] bytes (mallopt '
                         f'takes an int), got {value}')
    return value


def tune_glibc_malloc(mmap_threshold: int, trim_threshold: int) -> bool:
    """Set glibc's mmap and trim thresholds for this process.

    Allocations below ``mmap_threshold`` bytes come from the heap, and
    freed heap memory is returned to the kernel only beyond
    ``trim_threshold`` bytes at its top: both fixed, which also turns off
    glibc's dynamic threshold.

    Args:
        mmap_threshold (int): Bytes, at most 2**31 - 1.
        trim_threshold (int): Bytes, at most 2**31 - 1.

    Returns:
        bool: Whether glibc took both settings (False on another C library,
        e.g. macOS or musl, where nothing is changed).

    Raises:
        ValueError: If a threshold is not in [0, 2**31 - 1].
    """
    mmap_threshold = checked_threshold('mmap_threshold', mmap_threshold)
    trim_threshold = checked_threshold('trim_threshold', trim_threshold)
    libc = glibc()
    if libc is None:
        return False
    ok_mmap = libc.mallopt(M_MMAP_THRESHOLD, ctypes.c_int(mmap_threshold))
    ok_trim = libc.mallopt(M_TRIM_THRESHOLD, ctypes.c_int(trim_threshold))
    return bool(ok_mmap) and bool(ok_trim)
