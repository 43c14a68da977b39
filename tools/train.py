"""Train a model from a config (mmdet3d 1.x ``tools/train.py`` interface).

The models, datasets and hooks come from the config's ``custom_imports``;
the script itself imports only helpers of ``projects.occ_common.utils``
(CPU process groups, config checks). Flags and behaviour follow mmdet3d
1.4's script; ``--cfg-options`` and the config's top-level keys are
checked first (``config_checks``; an override of the wrong kind ends the
run with one line and exit status 2), and ``--resume`` resumes from the
complete checkpoint of the latest step of the work dir even without a
``last_checkpoint`` pointer (``CheckpointRecoveryHook`` of the configs).
The script adds ``CheckpointMatchHook``: a ``load_from`` checkpoint whose
keys or shapes differ from the model's is refused unless
``--allow-key-mismatch``, and a ``--resume`` checkpoint of another model
(or whose optimizer / schedule values differ from the config's) always,
each naming the file and the first mismatched keys. The run owns its work
dir (``engine/run_lock.py``): a second run into a work dir in use, or a
run without ``--resume`` into one holding an earlier run's checkpoints,
ends with one line naming it.
"""
import argparse
import logging
import os
import os.path as osp
import sys

from mmengine.config import Config
from mmengine.logging import print_log
from mmengine.registry import RUNNERS
from mmengine.runner import Runner

from projects.occ_common.engine.config_checks import (CfgOptionsAction,
                                                      apply_cfg_options,
                                                      cfg_errors_exit)
from projects.occ_common.engine.cpu_dist import (finalize_distributed,
                                                 setup_distributed)
from projects.occ_common.engine.run_lock import WorkDirError, hold_work_dir


def parse_args(argv=None):
    """Parse the command line (same flags as mmdet3d 1.4's train.py)."""
    parser = argparse.ArgumentParser(description='Train a 3D model')
    parser.add_argument('config', help='train config file path')
    parser.add_argument('--work-dir', help='the dir to save logs and models')
    parser.add_argument(
        '--amp',
        action='store_true',
        default=False,
        help='enable automatic-mixed-precision training')
    parser.add_argument(
        '--auto-scale-lr',
        action='store_true',
        help='enable automatically scaling LR.')
    parser.add_argument(
        '--resume',
        nargs='?',
        type=str,
        const='auto',
        help='If specify checkpoint path, resume from it, while if not '
        'specify, try to auto resume from the latest checkpoint '
        'in the work directory.')
    parser.add_argument(
        '--sync_bn',
        choices=['none', 'torch', 'mmcv'],
        default='none',
        help='convert all BatchNorm layers in the model to SyncBatchNorm '
        '(SyncBN) or mmcv.ops.sync_bn.SyncBatchNorm (MMSyncBN) layers.')
    parser.add_argument(
        '--cfg-options',
        nargs='+',
        action=CfgOptionsAction,
        help='override some settings in the used config, the key-value pair '
        'in xxx=yyy format will be merged into config file. If the value to '
        'be overwritten is a list, it should be like key="[a,b]" or key=a,b '
        'It also allows nested list/tuple values, e.g. key="[(a,b),(c,d)]" '
        'Note that the quotation marks are necessary and that no white space '
        'is allowed.')
    parser.add_argument(
        '--launcher',
        choices=['none', 'pytorch', 'slurm', 'mpi'],
        default='none',
        help='job launcher')
    parser.add_argument(
        '--allow-key-mismatch',
        action='store_true',
        help='fine-tune from a load_from checkpoint whose keys or shapes '
        "differ from the model's (missing ones keep their initialisation); "
        'refused by default, and always for --resume')
    # torch.distributed.launch passes --local-rank; torchrun sets LOCAL_RANK.
    parser.add_argument('--local_rank', '--local-rank', type=int, default=0)
    args = parser.parse_args(argv)
    if 'LOCAL_RANK' not in os.environ:
        os.environ['LOCAL_RANK'] = str(args.local_rank)
    return args


def build_cfg(args) -> Config:
    """Load the config and apply the command-line overrides."""
    cfg = Config.fromfile(args.config)
    cfg.launcher = args.launcher
    apply_cfg_options(cfg, args)

    # work_dir priority: CLI > config > ./work_dirs/<config name>.
    if args.work_dir is not None:
        cfg.work_dir = args.work_dir
    elif cfg.get('work_dir', None) is None:
        cfg.work_dir = osp.join('./work_dirs',
                                osp.splitext(osp.basename(args.config))[0])

    if args.amp:
        optim_wrapper = cfg.optim_wrapper.get('type', 'OptimWrapper')
        if optim_wrapper == 'AmpOptimWrapper':
            print_log(
                'AMP training is already enabled in your config.',
                logger='current',
                level=logging.WARNING)
        else:
            assert optim_wrapper == 'OptimWrapper', (
                '`--amp` is only supported when the optimizer wrapper type is '
                f'`OptimWrapper` but got {optim_wrapper}.')
            cfg.optim_wrapper.type = 'AmpOptimWrapper'
            cfg.optim_wrapper.loss_scale = 'dynamic'

    if args.sync_bn != 'none':
        cfg.sync_bn = args.sync_bn

    if args.auto_scale_lr:
        if ('auto_scale_lr' in cfg and 'enable' in cfg.auto_scale_lr
                and 'base_batch_size' in cfg.auto_scale_lr):
            cfg.auto_scale_lr.enable = True
        else:
            raise RuntimeError('Can not find "auto_scale_lr" or '
                               '"auto_scale_lr.enable" or '
                               '"auto_scale_lr.base_batch_size" in your'
                               ' configuration file.')

    if args.resume == 'auto':
        cfg.resume = True
        cfg.load_from = None
    elif args.resume is not None:
        cfg.resume = True
        cfg.load_from = args.resume
    # Registered by projects.occ_common (the config's custom_imports).
    cfg.custom_hooks = list(cfg.get('custom_hooks', None) or []) + [
        dict(
            type='CheckpointMatchHook',
            allow_key_mismatch=args.allow_key_mismatch,
            training=True),
        dict(type='WorkDirLockHook')
    ]
    return cfg


def _warn(message: str) -> None:
    print_log(message, logger='current', level=logging.WARNING)


def main(argv=None):
    """Build the runner from the config and train."""
    args = parse_args(argv)
    with cfg_errors_exit():
        cfg = build_cfg(args)
    setup_distributed(cfg)
    try:
        # The work dir is this run's from before the Runner writes to it
        # (its config copy, logs) until the run ends.
        with hold_work_dir(cfg.work_dir, cfg.resume, _warn):
            if 'runner_type' not in cfg:
                runner = Runner.from_cfg(cfg)
            else:
                runner = RUNNERS.build(cfg)
            runner.train()
    except WorkDirError as err:
        sys.exit(f'{osp.basename(sys.argv[0] or "train.py")}: error: {err}')
    finalize_distributed()


if __name__ == '__main__':
    main()
