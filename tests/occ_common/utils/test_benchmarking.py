"""Tests of the peak-memory and timing helpers of the benchmark tools."""
import pytest
import torch

from projects.occ_common.utils.benchmarking import (PeakMemory, summarise,
                                                    timed_runs)


def test_peak_memory_sees_a_64_mib_tensor():
    """A 16 Mi-float tensor (64 MiB) written inside the block raises the
    CPU high-water mark by at least ~60 MiB over the value on entry; an
    empty block adds far less."""
    with PeakMemory('cpu') as big:
        tensor = torch.ones(16 * 2**20)
        del tensor
    with PeakMemory('cpu') as empty:
        pass
    assert big.kind == 'cpu_rss_high_water'
    assert big.added_bytes > 60 * 2**20
    assert big.peak_bytes >= big.added_bytes
    assert empty.added_bytes < 16 * 2**20


def test_timed_runs_and_summary():
    """warmup calls are not timed; 3 runs give 3 wall and CPU times. The
    summary of (1, 2, 3, 10): median 2.5, mean 4, quartiles 1.75 and 4.75
    (numpy's linear interpolation)."""
    calls = []
    runs = timed_runs(lambda: calls.append(1), 3, warmup=2)
    assert len(calls) == 5
    assert len(runs['wall_s']) == len(runs['cpu_s']) == 3
    assert all(t >= 0 for t in runs['wall_s'])
    stats = summarise([3.0, 1.0, 10.0, 2.0])
    assert (stats['median'], stats['mean'], stats['min'], stats['max']) == \
        (2.5, 4.0, 1.0, 10.0)
    assert (stats['p25'], stats['p75']) == pytest.approx((1.75, 4.75))
    assert summarise([5.0])['std'] == 0.0
