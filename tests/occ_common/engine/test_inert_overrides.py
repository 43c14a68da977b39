"""Overrides that would do nothing are errors, or are made to work.

Before: ``--resume`` with ``optim_wrapper.optimizer.lr=...`` trained on
with the checkpoint's learning rate without a word (``Runner.resume``
loads the optimizer's and the schedulers' state over the config's), and
``--cfg-options custom_imports...`` was never imported (``Config.fromfile``
imports the file's own imports while it reads it).
"""
import os.path as osp
import re
import sys

import pytest
from mmengine.config import Config

from projects.occ_common.engine.config_checks import (CfgOptionsError,
                                                      merge_cfg_options)
from projects.occ_common.fileio import load_checkpoint_file
from projects.occ_common.testing.tool_logs import REPO_ROOT, load_tool

CONFIG = osp.join(REPO_ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


def _train(work_dir, *options, resume=False):
    argv = [CONFIG, '--work-dir', str(work_dir)]
    argv += ['--resume'] if resume else []
    return load_tool('tools/train.py').main(
        argv + ['--cfg-options', *options])


@pytest.fixture(scope='module')
def trained(tmp_path_factory):
    """A toy work dir after epoch 1 of 2, trained with lr 0.2 given on the
    command line (the config says 0.5)."""
    work = tmp_path_factory.mktemp('resume_overrides')
    _train(work, 'train_cfg.max_epochs=1', 'optim_wrapper.optimizer.lr=0.2')
    return work


@pytest.mark.parametrize('option, named', [
    ('optim_wrapper.optimizer.lr=0.1',
     'optimizer param group 0 initial_lr 0.2 (config: 0.1)'),
    ('optim_wrapper.optimizer.momentum=0.5',
     'optimizer param group 0 momentum 0.9 (config: 0.5)'),
    ('param_scheduler.0.milestones=[2]',
     'param_scheduler[0] (MultiStepLR) milestones Counter({1: 1}) '
     '(config: Counter({2: 1}))'),
])
def test_resume_refuses_what_it_would_silently_undo(trained, tmp_path,
                                                    option, named):
    """Each override names the value the checkpoint would restore; the
    lr one also the schedule's base value it starts from."""
    with pytest.raises(ValueError, match=f'--resume: .*epoch_1.pth holds '
                       f"optimizer / schedule values other than the "
                       f"config's.*{re.escape(named)}"):
        _train(trained, 'train_cfg.max_epochs=2',
               'optim_wrapper.optimizer.lr=0.2', option, resume=True)
    assert not osp.exists(trained / 'epoch_2.pth')


def test_resume_with_the_runs_own_overrides_trains_on(trained):
    """The interrupted run's command with --resume and a longer schedule
    (max_epochs 1 -> 2) resumes: 8 iterations after epoch 2. The
    scheduler keeps the checkpoint's end (epoch 1), as mmengine resumes,
    so the lr stays the run's 0.2 (an uninterrupted 2-epoch run halves it
    at its milestone, epoch 1): a warning says so."""
    _train(trained, 'train_cfg.max_epochs=2',
           'optim_wrapper.optimizer.lr=0.2', resume=True)
    checkpoint = load_checkpoint_file(str(trained / 'epoch_2.pth'))
    assert checkpoint['meta']['iter'] == 8
    group = checkpoint['optimizer']['param_groups'][0]
    assert (group['initial_lr'], group['lr']) == (0.2, 0.2)
    log = max(trained.glob('*/*.log'), key=lambda p: p.stat().st_mtime)
    assert "param_scheduler[0] (MultiStepLR) keeps the checkpoint's end 1 " \
        '(the training length now gives 2)' in log.read_text()


def test_custom_imports_override_is_imported(tmp_path, monkeypatch):
    """A module named only on the command line is imported (before: the
    override was merged and never imported); one that does not exist
    is an error naming it."""
    (tmp_path / 'my_plugin_62.py').write_text('LOADED = True\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, 'my_plugin_62', raising=False)
    cfg = Config.fromfile(CONFIG)
    merge_cfg_options(cfg, {
        'custom_imports.imports':
        ['projects.occ_common', 'my_plugin_62']
    })
    assert sys.modules['my_plugin_62'].LOADED
    with pytest.raises(CfgOptionsError, match='custom_imports: .*'
                       'no_such_module_62'):
        merge_cfg_options(cfg, {'custom_imports.imports':
                                ['no_such_module_62']})
