"""tools/analysis_tools/benchmark.py on the toy config: keys, counts and
ratios."""
import json
import os.path as osp

import numpy as np
import pytest
import torch

from projects.occ_common.testing.tool_logs import load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


def _tool():
    return load_tool('tools/analysis_tools/benchmark.py')


def test_single_model_json(tmp_path, capsys):
    """Toy model: Conv3d(3, 3, 1) has 3 * 3 * 1 * 1 * 1 + 3 = 12 params."""
    out = tmp_path / 'bench.json'
    _tool().main([CONFIG, '--runs', '4', '--warmup', '1', '--device', 'cpu',
                  '--fuse-conv-bn', '--json', str(out)])
    report = json.loads(out.read_text())
    assert {'device', 'threads', 'warmup', 'torch', 'models'} <= set(report)
    (model, ) = report['models']
    assert model['params'] == model['trainable_params'] == 12
    assert model['folded_bn'] == 0  # the toy has no ResNet backbone
    assert model['model'] == 'ToyOccupancyModel' and model['batch_size'] == 1
    latency = model['latency_ms']
    assert len(latency['runs']) == 4
    assert 0 < latency['min'] <= latency['p25'] <= latency['median'] \
        <= latency['p75'] <= latency['max']
    assert latency['median'] == pytest.approx(np.median(latency['runs']))
    assert model['peak_memory_mb'] > 0 and model['forward_memory_mb'] >= 0
    assert model['memory_kind'] == 'cpu_rss_high_water'
    # Conv3d(3, 3, 1) on the toy's 8 x 8 x 4 grid: 256 voxels x 3 x 3
    # multiply-adds x 2 = 4,608 FLOP. The share is that work over the
    # median wall time and the matmul rate measured in the same run.
    assert model['gflop'] * 1e9 == pytest.approx(4608)
    assert len(model['cpu_ms']['runs']) == 4
    assert model['matmul_share'] == pytest.approx(
        model['gflop'] / (latency['median'] / 1000) / report['matmul_gflops'])
    # The reference rate is timed in each of the 4 rounds beside the model
    # (not once before it), and the share uses the median of those rounds.
    rounds = report['matmul_gflops_rounds']
    assert len(rounds['runs']) == 4
    assert report['matmul_gflops'] == pytest.approx(np.median(rounds['runs']))
    table = capsys.readouterr().out
    assert 'latency median (ms)' in table and 'ratio' not in table
    assert report['malloc'] == 'default' and 'malloc default' in table


def test_keep_freed_memory_tunes_glibc_before_the_models(monkeypatch,
                                                         capsys):
    """--keep-freed-memory sets the glibc thresholds (1 GiB, 2**31 - 1)
    before any model is built, and the table says so. The call is recorded
    instead of made: the test process's own allocator stays as it is."""
    tool = _tool()
    calls = []

    def tune(mmap_threshold, trim_threshold):
        calls.append((mmap_threshold, trim_threshold))
        return True

    built = []
    subject = tool.Subject
    monkeypatch.setattr(tool, 'tune_glibc_malloc', tune)
    monkeypatch.setattr(
        tool, 'Subject',
        lambda *a: built.append(len(calls)) or subject(*a))
    report = tool.main([CONFIG, '--runs', '1', '--warmup', '0', '--device',
                        'cpu', '--matmul-size', '0', '--keep-freed-memory'])
    assert calls == [(1 << 30, 2**31 - 1)] and built == [1]
    assert report['malloc'] == 'keeps freed memory'
    assert 'malloc keeps freed memory' in capsys.readouterr().out


def test_compare_identical_models(tmp_path, capsys):
    """--compare toy toy: params and GFLOP ratios exactly 1, the latency
    ratio the quotient of the two medians.

    Timings are not asserted: on a shared machine the ratio of two
    millisecond forwards has been measured at 153 under load. That the
    ratio is the quotient of the two reported medians is the checkable fact.
    """
    report = _tool().main([CONFIG, '--compare', CONFIG, '--runs', '5',
                           '--warmup', '2', '--device', 'cpu',
                           '--batch-size', '2'])
    assert len(report['models']) == 2
    assert report['models'][1]['batch_size'] == 2
    assert report['ratio']['params'] == 1.0
    assert report['ratio']['gflop'] == 1.0
    medians = [m['latency_ms']['median'] for m in report['models']]
    assert report['ratio']['latency_median'] == pytest.approx(
        medians[1] / medians[0])
    assert 'ratio 2/1' in capsys.readouterr().out


def test_ratios_and_argument_errors():
    """A zero denominator gives None; no runs is refused."""
    tool = _tool()
    first = dict(params=0, latency_ms=dict(median=2.0),
                 cpu_ms=dict(median=4.0), gflop=0.5, forward_memory_mb=0.5)
    second = dict(params=5, latency_ms=dict(median=3.0),
                  cpu_ms=dict(median=5.0), gflop=1.0, forward_memory_mb=4.0)
    assert tool.ratios(first, second) == dict(
        params=None, latency_median=1.5, cpu_median=1.25, gflop=2.0,
        forward_memory=None)
    with pytest.raises(SystemExit):
        tool.parse_args([CONFIG, '--runs', '0'])


def test_train_mode_steps_the_optimiser():
    """--train times ``train_step``: one call changes the toy's weights
    (SGD, lr 0.5), a prediction does not. Its GFLOP count the backward
    too: the 1x1x1 conv's 4,608 FLOP forward plus the 4,608 FLOP of its
    weight gradient (the input needs none), twice the prediction's."""
    tool = _tool()
    reports = {}
    for mode in ('predict', 'train'):
        args = tool.parse_args([CONFIG, '--device', 'cpu'] +
                               (['--train'] if mode == 'train' else []))
        subject = tool.Subject(CONFIG, None, args)
        before = [p.detach().clone() for p in subject.model.parameters()]
        subject.fresh_input()
        subject.predict()
        changed = any(not torch.equal(a, p)
                      for a, p in zip(before, subject.model.parameters()))
        assert changed == (mode == 'train')
        assert subject.model.training == (mode == 'train')
        reports[mode] = subject.static_report()
        assert reports[mode]['mode'] == mode
    assert reports['predict']['gflop'] * 1e9 == pytest.approx(4608)
    assert reports['train']['gflop'] * 1e9 == pytest.approx(2 * 4608)
    with pytest.raises(SystemExit):
        tool.parse_args([CONFIG, '--train', '--fuse-conv-bn'])


def test_eager_vs_compiled_times_the_config_twice(monkeypatch, capsys):
    """--eager-vs-compiled: the toy eager, then its test_step through
    torch.compile (here Dynamo with the eager backend, to keep the test
    fast; the tool's own default is inductor), in alternating rounds:
    GFLOP counted on the eager step in both (ratio exactly 1), the
    compiled step traced by Dynamo; --compare and no warm-up are
    refused."""
    graphs = []
    compile_ = torch.compile

    def counting(fn, mode=None, **kwargs):
        def backend(gm, example_inputs):
            graphs.append(gm)
            return gm.forward

        assert mode is None  # 'default' passes no mode
        return compile_(fn, backend=backend, **kwargs)

    monkeypatch.setattr(torch, 'compile', counting)
    torch._dynamo.reset()
    tool = _tool()
    report = tool.main([CONFIG, '--eager-vs-compiled', '--runs', '3',
                        '--warmup', '1', '--device', 'cpu',
                        '--matmul-size', '0'])
    eager, compiled = report['models']
    assert (eager['compiled'], compiled['compiled']) == (None, 'default')
    assert report['ratio']['gflop'] == 1.0 and compiled['gflop'] > 0
    assert len(compiled['latency_ms']['runs']) == 3
    assert graphs
    assert 'torch.compile' in capsys.readouterr().out
    for bad in (['--compare', CONFIG], ['--warmup', '0']):
        with pytest.raises(SystemExit):
            tool.parse_args([CONFIG, '--eager-vs-compiled', *bad])
