"""Peak memory and timing for the benchmark tools (tools/benchmark*.py).

Peak memory on CUDA is ``torch.cuda.max_memory_allocated`` during the
block. On CPU it is the process's resident-set high-water mark: before the
block freed heap is returned to the OS (``malloc_trim``) and Linux's mark is
reset (``/proc/self/clear_refs``), after it ``VmHWM`` is read; this counts
every allocator (torch's, spconv's C++ buffers), which Python's
``tracemalloc`` would not. Where ``clear_refs`` is not writable a 1 ms
``VmRSS`` sampling thread stands in.
"""
import ctypes
import gc
import statistics
import threading
import time
from typing import Callable, Dict, List, Optional

import numpy as np
import torch


def status_bytes(field: str) -> int:
    """A ``/proc/self/status`` field (given in kB) in bytes.

    Args:
        field (str): E.g. ``'VmRSS'`` or ``'VmHWM'``.

    Returns:
        int: Bytes.
    """
    with open('/proc/self/status') as f:
        for line in f:
            if line.startswith(field + ':'):
                return int(line.split()[1]) * 1024
    raise RuntimeError(f'/proc/self/status has no {field}.')


def _trim_heap() -> None:
    """Collect garbage and give freed heap back so RSS is what is used."""
    gc.collect()
    try:
        ctypes.CDLL('libc.so.6').malloc_trim(0)
    except OSError:  # not glibc: freed memory may stay resident
        pass


class PeakMemory:
    """Peak memory of the code run inside ``with`` (see the module doc).

    After ``__exit__``, ``peak_bytes`` is the high-water mark and
    ``added_bytes`` its excess over the value at ``__enter__``;
    ``hwm_reset`` says whether the kernel's mark was reset (False: the
    sampling thread measured).

    Args:
        device (torch.device | str): Where the block allocates. Defaults
            to 'cpu'.
    """

    def __init__(self, device='cpu') -> None:
        self.device = torch.device(device)
        self.peak_bytes = 0
        self.added_bytes = 0
        self.hwm_reset = False
        self.kind = ('cuda_max_allocated'
                     if self.device.type == 'cuda' else 'cpu_rss_high_water')
        self._before = 0
        self._sampler: Optional[threading.Thread] = None
        self._running = False

    def _sample(self) -> None:
        while self._running:
            self.peak_bytes = max(self.peak_bytes, status_bytes('VmRSS'))
            time.sleep(0.001)

    def __enter__(self) -> 'PeakMemory':
        if self.device.type == 'cuda':
            torch.cuda.synchronize(self.device)
            torch.cuda.reset_peak_memory_stats(self.device)
            self._before = torch.cuda.memory_allocated(self.device)
            return self
        _trim_heap()
        self._before = status_bytes('VmRSS')
        try:
            with open('/proc/self/clear_refs', 'w') as refs:
                refs.write('5')  # resets VmHWM to the current RSS
            self.hwm_reset = True
        except OSError:
            self._running = True
            self.peak_bytes = self._before
            self._sampler = threading.Thread(
                target=self._sample, daemon=True)
            self._sampler.start()
        return self

    def __exit__(self, *exc) -> None:
        if self.device.type == 'cuda':
            torch.cuda.synchronize(self.device)
            self.peak_bytes = torch.cuda.max_memory_allocated(self.device)
        elif self._sampler is not None:
            self._running = False
            self._sampler.join()
        else:
            self.peak_bytes = status_bytes('VmHWM')
        self.added_bytes = max(0, self.peak_bytes - self._before)


def timed_runs(run: Callable[[], object],
               runs: int,
               warmup: int = 0,
               device='cpu') -> Dict[str, List[float]]:
    """Wall and process CPU time of repeated calls, synchronised on CUDA.

    Args:
        run (Callable[[], object]): The call to time.
        runs (int): Timed calls.
        warmup (int): Untimed calls first (lazy imports, caches).
            Defaults to 0.
        device (torch.device | str): CUDA devices are synchronised
            before the clock stops. Defaults to 'cpu'.

    Returns:
        dict: ``wall_s`` and ``cpu_s``, one entry per timed call; CPU time
        counts all threads of the process, so it is far less sensitive
        than wall time to other jobs on a shared machine.
    """
    device = torch.device(device)

    def call():
        run()
        if device.type == 'cuda':
            torch.cuda.synchronize(device)

    for _ in range(warmup):
        call()
    walls, cpus = [], []
    for _ in range(runs):
        cpu = time.process_time()
        start = time.perf_counter()
        call()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
    return dict(wall_s=walls, cpu_s=cpus)


def summarise(times: List[float]) -> Dict[str, float]:
    """Median and spread of timed runs (any unit).

    Args:
        times (list[float]): One value per run.

    Returns:
        dict: ``median``, ``mean``, ``std``, ``min``, ``max``, ``p25``,
        ``p75`` and the ``runs`` themselves.
    """
    ordered = sorted(times)
    quartiles = (np.percentile(ordered, [25, 75]).tolist()
                 if len(ordered) > 1 else [ordered[0]] * 2)
    return dict(
        median=statistics.median(ordered),
        mean=statistics.fmean(ordered),
        std=statistics.stdev(ordered) if len(ordered) > 1 else 0.0,
        min=ordered[0],
        max=ordered[-1],
        p25=quartiles[0],
        p75=quartiles[1],
        runs=list(times))
