"""Evaluate a checkpoint (mmdet3d 1.x ``tools/test.py`` interface).

The models, datasets and hooks come from the config's ``custom_imports``;
the script itself imports only the harness of ``projects.occ_common``
(``engine``: CPU process groups, config checks; ``apis``: the unlabelled
pipeline). Flags and behaviour follow mmdet3d 1.4's script, without the
flags that cannot work here (``--show`` opens a window, which a headless
GPU server has not: ``--show-dir`` writes the pictures instead; ``--tta``
needs a test-time augmentation that no config defines), and with checks
added: the script adds ``CheckpointMatchHook``,
which installs the restricted checkpoint loader before anything is loaded
and refuses a checkpoint with non-finite weights, or whose keys or shapes
differ from the model's (unless ``--allow-key-mismatch``);
``--cfg-options`` and the config's top-level keys are checked by
``config_checks`` (an override of the wrong kind ends the run with one
line and exit status 2).

``--format-only`` (the ``format_only`` of mmdet3d's metrics): the metric
writes the predictions instead of scoring them (Occ3D ``<token>.npz`` and
their zip, or SurroundOcc ``.npy`` rows; see
``projects/occ_common/evaluation/occupancy_export.py``) to
``--submission-prefix`` (default ``<work_dir>/submission``), and the test
pipeline reads no labels, so a split without them (``v1.0-test``) runs.
``--submission-prefix`` alone writes the same files and scores too.
"""
import argparse
import copy
import os
import os.path as osp

from mmengine.config import Config
from mmengine.registry import RUNNERS
from mmengine.runner import Runner

from projects.occ_common.apis.unlabelled_pipeline import (innermost_dataset,
                                                          unlabelled_pipeline)
from projects.occ_common.engine.config_checks import (CfgOptionsAction,
                                                      apply_cfg_options,
                                                      cfg_errors_exit)
from projects.occ_common.engine.cpu_dist import (finalize_distributed,
                                                 setup_distributed)


def parse_args(argv=None):
    """Parse the command line (same flags as mmdet3d 1.4's test.py)."""
    # No abbreviations: mmdet3d's --show would otherwise read as --show-dir.
    parser = argparse.ArgumentParser(
        description='Test (and eval) a model', allow_abbrev=False)
    parser.add_argument('config', help='test config file path')
    parser.add_argument('checkpoint', help='checkpoint file')
    parser.add_argument(
        '--work-dir',
        help='the directory to save the file containing evaluation metrics')
    parser.add_argument(
        '--show-dir',
        help='directory where painted images will be saved. '
        'If specified, it will be automatically saved '
        'to the work_dir/timestamp/show_dir')
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
        '--format-only',
        action='store_true',
        help='write the predictions in the benchmark layout instead of '
        'scoring them; runs on a split without labels (v1.0-test)')
    parser.add_argument(
        '--submission-prefix',
        help='folder of the prediction files (default with --format-only: '
        '<work_dir>/submission)')
    parser.add_argument(
        '--allow-key-mismatch',
        action='store_true',
        help='evaluate a checkpoint whose keys or shapes differ from the '
        "model's (missing ones keep their initialisation); refused by "
        'default')
    parser.add_argument('--local_rank', '--local-rank', type=int, default=0)
    args = parser.parse_args(argv)
    if 'LOCAL_RANK' not in os.environ:
        os.environ['LOCAL_RANK'] = str(args.local_rank)
    return args


def trigger_visualization_hook(cfg: Config, args) -> Config:
    """Switch on drawing in the config's visualisation hook."""
    default_hooks = cfg.default_hooks
    if 'visualization' not in default_hooks:
        raise RuntimeError(
            'VisualizationHook must be included in default_hooks to use '
            '--show-dir; refer to the configs in configs/_base_.')
    visualization_hook = default_hooks['visualization']
    visualization_hook['draw'] = True
    visualization_hook['test_out_dir'] = args.show_dir
    return cfg


def set_format_only(cfg: Config, args) -> None:
    """Point the metrics at the submission folder; with ``--format-only``
    also stop them scoring and the test pipeline reading labels."""
    prefix = args.submission_prefix
    if prefix is None and args.format_only:
        prefix = osp.join(cfg.work_dir, 'submission')
    if prefix is None:
        return
    # The configs share one evaluator / dataloader dict between val and
    # test: change test's own copy.
    evaluator = copy.deepcopy(cfg.test_evaluator)
    metrics = evaluator if isinstance(evaluator, list) else [evaluator]
    for metric in metrics:
        metric['submission_prefix'] = prefix
        if args.format_only:
            metric['format_only'] = True
    cfg.test_evaluator = evaluator
    if not args.format_only:
        return
    # Nothing is scored, no prediction uses the labels, and the test split
    # has no lidarseg: the pipeline reads none.
    cfg.test_dataloader = copy.deepcopy(cfg.test_dataloader)
    dataset = innermost_dataset(cfg.test_dataloader.dataset)
    dataset.pipeline = unlabelled_pipeline(dataset.pipeline)


def build_cfg(args) -> Config:
    """Load the config and apply the command-line overrides."""
    cfg = Config.fromfile(args.config)
    cfg.launcher = args.launcher
    apply_cfg_options(cfg, args)

    if args.work_dir is not None:
        cfg.work_dir = args.work_dir
    elif cfg.get('work_dir', None) is None:
        cfg.work_dir = osp.join('./work_dirs',
                                osp.splitext(osp.basename(args.config))[0])

    cfg.load_from = args.checkpoint
    set_format_only(cfg, args)
    # Registered by projects.occ_common (the config's custom_imports).
    cfg.custom_hooks = list(cfg.get('custom_hooks', None) or []) + [
        dict(
            type='CheckpointMatchHook',
            allow_key_mismatch=args.allow_key_mismatch)
    ]
    if args.show_dir:
        cfg = trigger_visualization_hook(cfg, args)
    return cfg


def main(argv=None):
    """Build the runner from the config and run the test loop."""
    args = parse_args(argv)
    with cfg_errors_exit():
        cfg = build_cfg(args)
    setup_distributed(cfg)
    if 'runner_type' not in cfg:
        runner = Runner.from_cfg(cfg)
    else:
        runner = RUNNERS.build(cfg)
    runner.test()
    finalize_distributed()


if __name__ == '__main__':
    main()
