"""Tests of the peak-memory and timing helpers of the benchmark tools."""
import pytest
import torch

from projects.occ_common.analysis.benchmarking import (PeakMemory,
                                                       alternating_runs,
                                                       count_gflop,
                                                       matmul_call,
                                                       matmul_share,
                                                       round_medians,
                                                       summarise, timed_runs)


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


def test_alternating_runs_rotate_the_order():
    """Two calls, 1 warm-up and 3 timed rounds: rounds start with a, b, a,
    b (round r starts with call r mod 2), so the call log is
    a b | b a | a b | b a and each name gets 3 timings, not 4."""
    log = []
    times = alternating_runs(
        dict(a=lambda: log.append('a'), b=lambda: log.append('b')),
        rounds=3, warmup=1)
    assert ''.join(log) == 'abbaabba'
    assert set(times) == {'a', 'b'}
    assert all(len(t['wall_s']) == len(t['cpu_s']) == 3
               for t in times.values())


def test_count_gflop_of_a_linear_layer():
    """Linear(4, 3) on a batch of 2: one (2 x 4) @ (4 x 3) product,
    2 * 2 * 4 * 3 = 48 FLOP (the bias add is element-wise: not counted);
    a ReLU alone counts 0."""
    layer = torch.nn.Linear(4, 3)
    x = torch.ones(2, 4)
    with torch.no_grad():
        assert count_gflop(lambda: layer(x)) * 1e9 == pytest.approx(48)
        assert count_gflop(lambda: torch.relu(x)) == 0.0


def test_matmul_rate_and_share():
    """60 GFLOP in 1 s against 150 GFLOP/s is a share of 0.4; a zero time
    is refused by value."""
    # The call of the alternating rounds: a 64^3 product is 2 * 64^3 =
    # 524,288 FLOP, and it is the product of two fixed matrices.
    call, gflop = matmul_call(size=64)
    assert gflop * 1e9 == pytest.approx(524288)
    assert torch.equal(call(), call()) and call().shape == (64, 64)
    assert matmul_share(60.0, 1.0, 150.0) == pytest.approx(0.4)
    with pytest.raises(ValueError, match='positive time'):
        matmul_share(1.0, 0.0, 150.0)


def test_round_medians_keep_the_rounds():
    """Rounds of 3, 1, 2 s wall and 0.5, 0.25, 1.0 s CPU: medians 2 and
    0.5, the rounds kept as they were."""
    rounds = dict(wall_s=[3.0, 1.0, 2.0], cpu_s=[0.5, 0.25, 1.0])
    assert round_medians(dict(a=rounds)) == dict(
        a=dict(wall_s=2.0, cpu_s=0.5, rounds=rounds))
