"""Fault-matrix cases of training runs: work dirs, resumes, overrides and
process groups (see :mod:`.fault_cases`). The toy config trains in the
children; a work dir after its first epoch is made once per run."""
import json
import os
import os.path as osp
import socket
import sys
from typing import List

import torch

from . import hostile_files as hostile
from .fault_cases import (CLEAR, CONFIG, HANDLED, Case, DataLoss, Silent,
                          copy_toy_work_dir, kept)


def _train(work, *argv):
    from .tool_runs import load_tool
    return load_tool('tools/train.py').main(
        [CONFIG, '--work-dir', work, *argv])


def _epochs(count):
    return ['--cfg-options', f'train_cfg.max_epochs={count}']


# -- config text in a checkpoint ------------------------------------------


def _payload_checkpoint(folder, marker):
    """The toy run's epoch_1.pth with a payload in meta['config']."""
    source = osp.join(copy_toy_work_dir(folder, 'source'), 'epoch_1.pth')
    return hostile.write_config_payload(
        source, osp.join(folder, 'payload.pth'), marker)


def _planted_payload(folder, marker):
    """The same, planted as epoch_9.pth of a work dir of its own."""
    work = osp.join(folder, 'planted')
    os.makedirs(work)
    planted = osp.join(work, 'epoch_9.pth')
    os.replace(_payload_checkpoint(folder, marker), planted)
    return planted


# -- work dirs ------------------------------------------------------------


def _copied_work_dir(folder, marker):
    """epoch_1..3.pth as ``cp`` leaves them (epoch_1.pth copied last: the
    newest file time), the pointer on epoch_3.pth."""
    return _steps(folder, 'epoch_1.pth')


def _steps(folder, returned):
    for step in (1, 2, 3):
        path = osp.join(folder, f'epoch_{step}.pth')
        torch.save(dict(meta=dict(epoch=step, iter=step), state_dict={}),
                   path)
        os.utime(path, (4e6 - step * 1e6, ) * 2)
    with open(osp.join(folder, 'last_checkpoint'), 'w') as f:
        f.write(osp.join(folder, 'epoch_3.pth'))
    return osp.join(folder, returned)


def _bracketed(folder, marker):
    """epoch_1..3.pth in a work dir named ``exp[1]``, no pointer."""
    work = osp.join(folder, 'exp[1]')
    os.makedirs(work)
    path = _steps(work, 'epoch_1.pth')
    os.remove(osp.join(work, 'last_checkpoint'))
    return path


def _auto_resume_target(path):
    """tools/train.py --resume in the work dir: the pointer must name the
    latest step (else a resume from scratch over them: data loss)."""
    from ..engine.hooks.checkpoint_recovery_hook import repair_work_dir
    folder = osp.dirname(path)
    repair_work_dir(folder)
    pointer = osp.join(folder, 'last_checkpoint')
    target = open(pointer).read() if osp.isfile(pointer) else ''
    if not target.endswith('epoch_3.pth'):
        raise DataLoss('--resume would train over epoch_1..3.pth from '
                       f'{target or "scratch"}')
    return target


def _resume_before_later_steps(path):
    """tools/train.py --resume epoch_1.pth next to epoch_2/3.pth."""
    from ..engine.hooks.checkpoint_recovery_hook import \
        check_no_later_checkpoint
    check_no_later_checkpoint(osp.dirname(path), path)
    raise DataLoss('--resume epoch_1.pth would overwrite epoch_2/3.pth')


def _in_use(folder, marker):
    """A toy work dir whose lock names a live run of this host: the
    parent (the matrix itself)."""
    from ..engine.run_lock import LOCK_NAME, _start_time
    work = copy_toy_work_dir(folder)
    with open(osp.join(work, LOCK_NAME), 'w') as f:
        json.dump(dict(host=socket.gethostname(), pid=os.getpid(),
                       start=_start_time(os.getpid()), token='first',
                       started='now', command='the first run'), f)
    return work


def _toy_copy(folder, marker):
    return copy_toy_work_dir(folder)


def _checkpoint_of(work):
    return [osp.join(work, 'epoch_1.pth')]


def _run_files(work):
    """The first run's checkpoint and pointer (a second run resuming
    there rewrites the pointer under it)."""
    return [osp.join(work, 'epoch_1.pth'), osp.join(work, 'last_checkpoint')]


def _symlinked_pointer(folder, marker):
    """A toy work dir whose last_checkpoint links to a file of the user's
    (naming epoch_1.pth)."""
    work = copy_toy_work_dir(folder)
    mine = osp.join(folder, 'my_latest.txt')
    os.replace(osp.join(work, 'last_checkpoint'), mine)
    os.symlink(mine, osp.join(work, 'last_checkpoint'))
    return work


# -- overrides -----------------------------------------------------------


def _lr_ignored(work):
    """Resume with another lr: it must be refused, or used."""
    from ..fileio import load_checkpoint_file
    _train(work, '--resume', '--cfg-options', 'train_cfg.max_epochs=2',
           'optim_wrapper.optimizer.lr=0.1')
    group = load_checkpoint_file(osp.join(
        work, 'epoch_2.pth'))['optimizer']['param_groups'][0]
    if group['initial_lr'] != 0.1:
        raise Silent(f'--resume trained on with lr {group["initial_lr"]}, '
                     'not the 0.1 given')


def _plugin(folder, marker):
    path = osp.join(folder, 'plugin_62.py')
    with open(path, 'w') as f:
        f.write('LOADED = True\n')
    return path


def _custom_imports(path):
    """tools/train.py's config step with a custom_imports override."""
    from .tool_runs import load_tool
    sys.path.insert(0, osp.dirname(path))
    train = load_tool('tools/train.py')
    train.build_cfg(train.parse_args([
        CONFIG, '--cfg-options',
        'custom_imports.imports=[projects.occ_common,plugin_62]'
    ]))
    if 'plugin_62' not in sys.modules:
        raise Silent('the custom_imports override was not imported')


# -- process groups --------------------------------------------------------


def _port(folder, marker):
    from .ddp_check import free_port
    path = osp.join(folder, 'port')
    with open(path, 'w') as f:
        f.write(str(free_port()))
    return path


def _rank_alone(path):
    """Rank 0 of 2 under torchrun's variables, no rank 1, a 3 s deadline:
    what tools/train.py and tools/test.py do first."""
    from mmengine.config import Config

    from ..engine.cpu_dist import setup_distributed
    os.environ.update(RANK='0', LOCAL_RANK='0', WORLD_SIZE='2',
                      MASTER_ADDR='127.0.0.1', MASTER_PORT=open(path).read(),
                      OCC_DIST_INIT_TIMEOUT='3')
    setup_distributed(Config(dict(launcher='pytorch', env_cfg=dict(
        dist_cfg=dict(backend='gloo')))))


def _rank_and_address(path):
    return ['rank 0 of 2', f'127.0.0.1:{open(path).read()}']


#: Training runs, their work dirs and overrides.
RUN_CASES: List[Case] = [
    Case('config text in a checkpoint\'s meta: tools/train.py --resume '
         'PATH', HANDLED, _payload_checkpoint,
         lambda path: _train(osp.join(osp.dirname(path), 'work'),
                             '--resume', path, *_epochs(2)),
         guards=('config text dropped', )),
    Case('config text in a checkpoint planted as epoch_9.pth: --resume',
         HANDLED, _planted_payload,
         lambda path: _train(osp.dirname(path), '--resume', *_epochs(2))),
    Case('work dir copied with cp (file times reversed): --resume',
         HANDLED, _copied_work_dir, _auto_resume_target),
    Case('--resume epoch_1.pth next to epoch_2/3.pth', CLEAR,
         _copied_work_dir, _resume_before_later_steps,
         guards=('later checkpoints kept', )),
    Case('work dir named exp[1]: --resume', HANDLED, _bracketed,
         _auto_resume_target, guards=('glob-safe listing', )),
    Case('--resume exp[1]/epoch_1.pth next to epoch_2/3.pth', CLEAR,
         _bracketed, _resume_before_later_steps,
         guards=('glob-safe listing', )),
    Case('second run into a work dir in use: tools/train.py --resume',
         CLEAR, _in_use,
         kept(lambda work: _train(work, '--resume', *_epochs(2)),
              _run_files), guards=('lock refuses', )),
    Case('finished run re-run without --resume: tools/train.py', CLEAR,
         _toy_copy, kept(lambda work: _train(work, *_epochs(1)),
                         _checkpoint_of),
         guards=('earlier run kept', )),
    Case('last_checkpoint a symlink to a user\'s file: --resume', HANDLED,
         _symlinked_pointer,
         kept(lambda work: _train(work, '--resume', *_epochs(2)),
              lambda work: [osp.join(osp.dirname(work), 'my_latest.txt')]),
         guards=('pointer not followed', )),
    Case('lr override with --resume: tools/train.py', CLEAR,
         _toy_copy, _lr_ignored, guards=('resume overrides', )),
    Case('custom_imports override: tools/train.py', HANDLED, _plugin,
         _custom_imports, guards=('custom_imports imported', )),
    Case('a missing distributed peer: tools/train.py --launcher pytorch',
         CLEAR, _port, _rank_alone, names=_rank_and_address, timeout=60,
         guards=('rendezvous deadline', )),
]

__all__ = ['RUN_CASES']
