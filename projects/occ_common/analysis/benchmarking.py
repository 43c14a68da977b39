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
from typing import Callable, Dict, List, Optional, Tuple

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


def alternating_runs(
        calls: Dict[str, Callable[[], object]],
        rounds: int,
        warmup: int = 0,
        device='cpu',
        before: Optional[Dict[str, Callable[[], object]]] = None
) -> Dict[str, Dict[str, List[float]]]:
    """Time several calls in alternating rounds, for A/B comparisons.

    On a shared machine the load drifts over seconds; timing model A's runs
    and then model B's puts that drift into their ratio. Here every round
    times each call once, and the order rotates from round to round
    (round ``r`` starts with call ``r mod n``) so that no call always runs
    right after another's allocations.

    Args:
        calls (dict[str, Callable[[], object]]): Name -> call to time.
        rounds (int): Timed rounds.
        warmup (int): Untimed rounds first. Defaults to 0.
        device (torch.device | str): CUDA devices are synchronised
            before each clock stops. Defaults to 'cpu'.
        before (dict[str, Callable[[], object]], optional): Name -> an
            untimed call made right before each of that name's calls (e.g.
            a fresh copy of an input the call consumes).

    Returns:
        dict: Name -> ``{'wall_s': [...], 'cpu_s': [...]}``, one entry per
        round, as :func:`timed_runs` gives them.
    """
    before = before or {}
    names = list(calls)
    times = {name: dict(wall_s=[], cpu_s=[]) for name in names}
    for r in range(warmup + rounds):
        start = r % len(names)
        for name in names[start:] + names[:start]:
            if name in before:
                before[name]()
            one = timed_runs(calls[name], 1, device=device)
            if r >= warmup:
                times[name]['wall_s'] += one['wall_s']
                times[name]['cpu_s'] += one['cpu_s']
    return times


def round_medians(
        times: Dict[str, Dict[str, List[float]]]) -> Dict[str, dict]:
    """The medians of :func:`alternating_runs`'s rounds, per call.

    Args:
        times (dict): Name -> ``{'wall_s': [...], 'cpu_s': [...]}``.

    Returns:
        dict: Name -> ``{'wall_s': median, 'cpu_s': median, 'rounds':
        the per-round times}``.
    """
    return {
        name: dict(
            wall_s=statistics.median(t['wall_s']),
            cpu_s=statistics.median(t['cpu_s']),
            rounds=t)
        for name, t in times.items()
    }


def count_gflop(run: Callable[[], object]) -> float:
    """GFLOP of one call, by ``torch.utils.flop_counter``.

    Counts the aten operators the counter knows (matmuls, convolutions,
    attention: 2 FLOP per multiply-add); element-wise work and custom
    operators (spconv's sparse convolutions, mmcv's scatter) count zero, so
    this is the model's dense-algebra work, the part the matmul rate of
    :func:`matmul_call`'s rate is the ceiling for.

    Args:
        run (Callable[[], object]): The call (run once, under no_grad if
            it should be).

    Returns:
        float: Billions of floating-point operations.
    """
    from torch.utils.flop_counter import FlopCounterMode
    counter = FlopCounterMode(display=False)
    with counter:
        run()
    return counter.get_total_flops() / 1e9


def matmul_call(size: int = 2048,
                device='cpu') -> Tuple[Callable[[], object], float]:
    """One fp32 ``size``-cube ``torch.mm`` on fixed matrices, and its work.

    Timed as one more subject of :func:`alternating_runs`, beside the
    models, its rate in each round is the reference the models' rates are
    a share of, measured under the same load as they are.

    Args:
        size (int): Side of the square matrices (2 size^3 FLOP per
            product). Defaults to 2048.
        device (torch.device | str): Defaults to 'cpu'.

    Returns:
        tuple: The call, and its GFLOP.
    """
    gen = torch.Generator().manual_seed(0)
    a = torch.randn(size, size, generator=gen).to(device)
    b = torch.randn(size, size, generator=gen).to(device)
    return (lambda: torch.mm(a, b)), 2.0 * size**3 / 1e9


def matmul_share(gflop: float, seconds: float, rate_gflops: float) -> float:
    """The share of the matmul rate a run achieved: (GFLOP / s) / rate.

    Args:
        gflop (float): Work of the run (:func:`count_gflop`).
        seconds (float): Its wall time.
        rate_gflops (float): The matmul rate (:func:`matmul_call`).

    Returns:
        float: E.g. 0.4 for 60 GFLOP in 1 s against 150 GFLOP/s.
    """
    if seconds <= 0 or rate_gflops <= 0:
        raise ValueError(f'expected positive time and rate, got {seconds} s '
                         f'and {rate_gflops} GFLOP/s.')
    return gflop / seconds / rate_gflops
