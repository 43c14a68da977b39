"""--resume continues the global random streams: the random state of every
rank is saved in each checkpoint and restored where the uninterrupted run
would draw next.

The toy config with ``Dropout3d`` on its inputs (torch's global generator,
as DropPath's) trains 2 epochs with a validation after each; a run resumed
from its epoch_1.pth must end with the same weights. Before
RandomStateHook the resumed run drew other dropout masks (its generator
restarted from the seed). The OccCylindrical run is in
``tests/tools/test_kill_resume.py``.
"""
import random
import shutil
import types
import uuid

import numpy as np
import pytest
import torch
from mmengine.config import Config
from mmengine.hooks import CheckpointHook
from mmengine.runner import Runner

from projects.occ_common.engine.hooks import RandomStateHook
from projects.occ_common.engine.hooks import random_state_hook as hook_module
from projects.occ_common.engine.hooks.random_state_hook import (
    get_random_state, set_random_state)
from projects.occ_common.fileio import load_checkpoint_file
from projects.occ_common.testing.tool_logs import REPO_ROOT

CONFIG = f'{REPO_ROOT}/tests/data/configs/toy_occ.py'
EPOCHS = 2


def _draws():
    return (torch.rand(3), np.random.rand(3), random.random())


def _same(a, b):
    return (torch.equal(a[0], b[0]) and np.array_equal(a[1], b[1])
            and a[2] == b[2])


def test_state_round_trips_through_the_restricted_loader(tmp_path):
    """The ByteTensor, numpy and Python states load through
    load_checkpoint_file (also onto another device: map_location) and
    repeat the draws; a malformed state is an error naming the file."""
    state = get_random_state()
    expected = _draws()
    torch.save({'rng_state': {'world_size': 1, 'ranks': [state]}},
               tmp_path / 'x.pth')
    loaded = load_checkpoint_file(str(tmp_path / 'x.pth'), 'cpu')
    saved = loaded['rng_state']['ranks'][0]
    assert saved['torch'].dtype == torch.uint8
    set_random_state(saved)
    assert _same(_draws(), expected)
    with pytest.raises(ValueError, match='x.pth: its rng_state is not'):
        set_random_state(dict(saved, torch=torch.zeros(3)), 'x.pth')


def _cfg(work_dir, persistent=False, **extra):
    cfg = Config.fromfile(CONFIG, format_python_code=False)
    cfg.merge_from_dict({
        'model.dropout': 0.5,
        'train_cfg.max_epochs': EPOCHS,
        'default_hooks.checkpoint.max_keep_ckpts': EPOCHS,
        'randomness.deterministic': True,
        **extra
    })
    if persistent:
        cfg.train_dataloader.update(num_workers=1, persistent_workers=True)
    cfg.work_dir = str(work_dir)
    cfg.experiment_name = f'random_state_{uuid.uuid4().hex}'
    return cfg


def _state_dict(path):
    return load_checkpoint_file(str(path), 'cpu')['state_dict']


@pytest.fixture
def deterministic_restored():
    """randomness.deterministic switches torch's flag for the process:
    put it back for the next tests."""
    before = torch.are_deterministic_algorithms_enabled()
    yield
    torch.use_deterministic_algorithms(before)


@pytest.mark.parametrize('persistent', [False, True],
                         ids=['new iterator each epoch', 'persistent workers'])
def test_resume_repeats_the_dropout_of_an_uninterrupted_run(
        tmp_path, persistent, deterministic_restored):
    """Resumed from epoch_1.pth: epoch_2.pth equals the straight run's,
    with a data loader that draws a seed each epoch (restored before it)
    or persistent workers (restored before the first iteration)."""
    straight = tmp_path / 'straight'
    Runner.from_cfg(_cfg(straight, persistent)).train()
    resumed = tmp_path / 'resumed'
    resumed.mkdir()
    shutil.copy(straight / 'epoch_1.pth', resumed / 'epoch_1.pth')
    cfg = _cfg(resumed, persistent)
    cfg.resume, cfg.load_from = True, str(resumed / 'epoch_1.pth')
    Runner.from_cfg(cfg).train()
    expected = _state_dict(straight / f'epoch_{EPOCHS}.pth')
    got = _state_dict(resumed / f'epoch_{EPOCHS}.pth')
    assert all(torch.equal(got[k], v) for k, v in expected.items())


def _fake_runner(rank=0, world_size=2, **cfg):
    checkpoint_hook = CheckpointHook(interval=1)
    return types.SimpleNamespace(
        hooks=[checkpoint_hook], rank=rank, world_size=world_size, epoch=0,
        iter=3, max_epochs=4, cfg=Config(cfg), work_dir='work',
        logger=types.SimpleNamespace(warning=print))


def test_every_rank_saves_and_gets_back_its_own_state(monkeypatch):
    """With two ranks the states are gathered when the checkpoint hook
    saves (and only then), stored as ranks [0, 1], and rank 1 restores
    the second."""
    mine, other = get_random_state(), get_random_state()
    other['torch'] = torch.random.manual_seed(7).get_state()
    calls = []
    monkeypatch.setattr(hook_module, 'all_gather_object',
                        lambda obj: calls.append(obj) or [mine, other])
    hook, runner = RandomStateHook(), _fake_runner()
    hook.after_train_iter(runner, 0)  # the hook saves by epoch: no gather
    assert calls == []
    hook.after_train_epoch(runner)
    checkpoint = {}
    hook.before_save_checkpoint(runner, checkpoint)
    assert checkpoint['rng_state']['world_size'] == 2
    assert checkpoint['rng_state']['ranks'][1] is other

    rank1 = _fake_runner(rank=1, resume=True, load_from='ckpt.pth')
    hook = RandomStateHook()
    hook.after_load_checkpoint(rank1, checkpoint)
    torch.random.manual_seed(0)
    hook.before_train_iter(rank1, 0)
    got = torch.rand(3)
    torch.random.manual_seed(7)
    assert torch.equal(got, torch.rand(3))
