"""MainProcessLoggerHook: under distributed testing only rank 0 writes the
test metrics json (every rank rewrote it with mmengine's LoggerHook)."""
import json
import os.path as osp
from types import SimpleNamespace

import pytest
from mmengine.config import Config
from mmengine.hooks import LoggerHook

from projects.occ_common.engine.hooks import MainProcessLoggerHook
from projects.occ_common.testing.tool_logs import REPO_ROOT as ROOT

RECORD = {'occ/mIoU': 41.5, 'time': 0.25}


def _runner(log_dir):
    """What ``after_test_epoch`` reads of a runner: 3 test batches whose
    epoch record is RECORD; the logged lines are kept in ``lines``."""
    lines = []
    processor = SimpleNamespace(
        get_log_after_epoch=lambda runner, n, mode, with_non_scalar: (
            dict(RECORD), f'Epoch({mode}) [{n}/{n}] occ/mIoU: 41.5000'))
    return SimpleNamespace(log_dir=str(log_dir), test_dataloader=[0, 1, 2],
                           log_processor=processor,
                           logger=SimpleNamespace(info=lines.append),
                           lines=lines)


def _test_epoch(hook_type, rank, log_dir, monkeypatch):
    """Run ``after_test_epoch`` of a ``hook_type`` as the given rank."""
    monkeypatch.setattr('mmengine.dist.utils.get_rank',
                        lambda group=None: rank)
    hook = hook_type()
    hook.json_log_path = '20261127_000000.json'  # set by before_run
    runner = _runner(log_dir)
    hook.after_test_epoch(runner, metrics={'occ/mIoU': 41.5})
    return runner.lines, osp.join(str(log_dir), hook.json_log_path)


@pytest.mark.parametrize('hook_type', [LoggerHook, MainProcessLoggerHook])
def test_rank_zero_writes_the_record_and_logs_the_line(
        hook_type, tmp_path, monkeypatch):
    """Single-process and rank 0 behave as mmengine's hook: the record is
    the json file's one line, and the log line is logged."""
    lines, path = _test_epoch(hook_type, 0, tmp_path, monkeypatch)
    assert lines == ['Epoch(test) [3/3] occ/mIoU: 41.5000']
    with open(path) as f:
        assert [json.loads(line) for line in f] == [RECORD]


def test_other_ranks_log_the_line_but_write_no_file(tmp_path, monkeypatch):
    """Rank 1 logs the same line; only mmengine's hook also (re)writes the
    shared json file, which is the race this hook removes."""
    lines, path = _test_epoch(MainProcessLoggerHook, 1, tmp_path, monkeypatch)
    assert lines == ['Epoch(test) [3/3] occ/mIoU: 41.5000']
    assert not osp.exists(path)

    _, upstream_path = _test_epoch(LoggerHook, 1, tmp_path, monkeypatch)
    assert upstream_path == path and osp.exists(path)


def test_default_runtime_uses_it():
    """Every config inherits the logger of default_runtime.py."""
    cfg = Config.fromfile(osp.join(ROOT, 'configs', '_base_',
                                   'default_runtime.py'))
    assert cfg.default_hooks.logger == dict(type='MainProcessLoggerHook',
                                            interval=50)
