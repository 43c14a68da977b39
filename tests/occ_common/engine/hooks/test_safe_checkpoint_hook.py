"""Saving never leaves fewer than one complete checkpoint, and --resume
finds it, whatever interrupts the save.

The toy config trains 3 epochs of 4 iterations with ``max_keep_ckpts=1``
(the tiny configs' setting), a checkpoint per epoch. mmengine's own
CheckpointHook deletes epoch_1.pth *before* it writes epoch_2.pth, so each
fault below used to leave no checkpoint at all (and ``--resume`` silently
started from scratch). Runs that must die by SIGKILL run as a subprocess;
the others in this process.
"""
import os
import os.path as osp
import signal
import subprocess
import sys
import uuid

import pytest
import torch
from mmengine.config import Config
from mmengine.runner import Runner

import projects.occ_common.testing.faults  # noqa: F401  (registers)
from projects.occ_common.engine.hooks import SafeCheckpointHook
from projects.occ_common.fileio import load_checkpoint_file
from projects.occ_common.fileio.atomic_file_backend import is_temporary_file
from projects.occ_common.testing.tool_logs import REPO_ROOT as ROOT

CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ_faults.py')
OPTIONS = {
    'train_cfg.max_epochs': 3,
    'train_cfg.val_interval': 100,
    'default_hooks.checkpoint.max_keep_ckpts': 1,
    'randomness.deterministic': True,
}


def _cfg(work_dir, fault=None, at_call=None, resume=False):
    cfg = Config.fromfile(CONFIG)
    cfg.merge_from_dict(OPTIONS)
    cfg.work_dir = str(work_dir)
    cfg.experiment_name = f'safe_ckpt_{uuid.uuid4().hex}'
    if fault is not None:
        cfg.default_hooks.checkpoint.backend_args = dict(
            backend='faulty_local', fault=fault, at_call=at_call)
    cfg.resume = resume
    return cfg


def _train(cfg):
    runner = Runner.from_cfg(cfg)
    runner.train()
    return runner


def _state_dict(path):
    return load_checkpoint_file(path, map_location='cpu')['state_dict']


def _train_in_subprocess(work_dir, fault, at_call):
    """tools/train.py with the faulty backend; returns the process."""
    options = [f'{key}={value}' for key, value in OPTIONS.items()]
    options += [
        'default_hooks.checkpoint.backend_args.backend=faulty_local',
        f'default_hooks.checkpoint.backend_args.fault={fault}',
        f'default_hooks.checkpoint.backend_args.at_call={at_call}'
    ]
    return subprocess.run([
        sys.executable,
        osp.join(ROOT, 'tools', 'train.py'), CONFIG, '--work-dir',
        str(work_dir), '--cfg-options', *options
    ],
                          cwd=ROOT,
                          capture_output=True,
                          text=True,
                          timeout=300)


@pytest.fixture(scope='module')
def straight(tmp_path_factory):
    """epoch_3.pth's weights of an uninterrupted run."""
    work_dir = tmp_path_factory.mktemp('straight')
    _train(_cfg(work_dir))
    return _state_dict(osp.join(work_dir, 'epoch_3.pth'))


def _files(work_dir):
    return sorted(os.listdir(work_dir))


@pytest.mark.slow
@pytest.mark.parametrize('fault, at_call', [('sigkill', 2), ('sigint', 2),
                                            ('enospc', 2),
                                            ('sigkill_after', 1)])
def test_interrupted_save_resumes_from_the_last_complete_checkpoint(
        fault, at_call, straight, tmp_path, monkeypatch):
    """Fault while writing epoch_2.pth (or right after epoch_1.pth, before
    its pointer): epoch_1.pth survives, --resume continues from it and
    ends with the weights of the uninterrupted run."""
    work_dir = tmp_path / 'work'
    if fault.startswith('sigkill'):
        proc = _train_in_subprocess(work_dir, fault, at_call)
        assert proc.returncode == -signal.SIGKILL, proc.stderr[-3000:]
    else:
        expected = KeyboardInterrupt if fault == 'sigint' else OSError
        with pytest.raises(expected):
            _train(_cfg(work_dir, fault, at_call))
    files = _files(work_dir)
    assert 'epoch_1.pth' in files and 'epoch_2.pth' not in files
    assert set(_state_dict(work_dir / 'epoch_1.pth')) == set(straight)
    temporary = [f for f in files if is_temporary_file(f)]
    # Only a kill mid-write leaves the partial temporary file behind.
    assert len(temporary) == (1 if fault == 'sigkill' else 0)
    assert ('last_checkpoint' in files) == (fault != 'sigkill_after')

    resumed_from = []
    resume = Runner.resume

    def spy(self, filename, *args, **kwargs):
        resumed_from.append(filename)
        return resume(self, filename, *args, **kwargs)

    monkeypatch.setattr(Runner, 'resume', spy)
    runner = _train(_cfg(work_dir, resume=True))
    assert resumed_from == [str(work_dir / 'epoch_1.pth')]
    assert (runner.epoch, runner.iter) == (3, 12)
    resumed = _state_dict(work_dir / 'epoch_3.pth')
    assert list(resumed) == list(straight)
    for name, tensor in straight.items():
        assert torch.equal(resumed[name], tensor), name
    # Rotation went on: only the newest checkpoint and no partial write.
    assert [f for f in _files(work_dir)
            if f.endswith('.pth') or f.endswith('.tmp')] == ['epoch_3.pth']


def test_unknown_argument_is_refused_when_the_hook_is_built():
    """A key typo fails at build, not after an epoch at the first save.

    mmengine's CheckpointHook passes unknown keys on to
    Runner.save_checkpoint, which raises TypeError at the first save.
    """
    with pytest.raises(TypeError,
                       match="unknown argument 'max_keep_ckpt' \\(did you "
                       "mean 'max_keep_ckpts'\\?\\)"):
        SafeCheckpointHook(interval=1, max_keep_ckpt=1)
    hook = SafeCheckpointHook(interval=1, max_keep_ckpts=2)
    assert hook.backend_args == dict(backend='atomic_local')


def test_checkpoint_failing_verification_keeps_the_old_one(
        tmp_path, monkeypatch):
    """A new file that does not read back: the old one and the pointer
    stay, and the error names the file."""
    cfg = _cfg(tmp_path, resume=False)
    cfg.train_cfg.max_epochs = 2
    from projects.occ_common.engine.hooks import safe_checkpoint_hook
    real = safe_checkpoint_hook.load_checkpoint_file
    calls = []

    def fail_second(path, map_location=None):
        calls.append(path)
        if len(calls) == 2:
            raise ValueError('simulated bit rot')
        return real(path, map_location)

    monkeypatch.setattr(safe_checkpoint_hook, 'load_checkpoint_file',
                        fail_second)
    with pytest.raises(RuntimeError,
                       match='the checkpoint just written, .*epoch_2.pth, '
                       'does not load back .*simulated bit rot'):
        _train(cfg)
    assert 'epoch_1.pth' in _files(tmp_path)
    with open(tmp_path / 'last_checkpoint') as f:
        assert f.read().endswith('epoch_1.pth')
