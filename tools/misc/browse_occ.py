#!/usr/bin/env python
"""Browse occupancy in 3D in a web browser: served, or one exported file.

Serve a config's test split on one port of the machine that holds the data
(a headless GPU box) and open it from a laptop through SSH port forwarding::

    python tools/misc/browse_occ.py CONFIG [--checkpoint CKPT |
        --pred-dir DIR] [--port 8765]
    # on the laptop: ssh -N -L 8765:localhost:8765 user@gpu-box
    # then open http://localhost:8765

or write one self-contained HTML file of a sample (no server, no network
needed to open it)::

    python tools/misc/browse_occ.py CONFIG [--checkpoint CKPT] \\
        --export-html OUT.html --sample-idx N [--cfg-options ...]

The page shows the ground truth by class, the prediction (``--checkpoint``
runs the model, loaded with the checks of ``tools/test.py``;
``--pred-dir`` reads the files of ``tools/test.py --format-only``) and the
error view (true positives, false positives, misses, wrong class), the
LiDAR points (by height, intensity or lidarseg class), the camera frusta
with their images, Occ3D's camera / LiDAR visibility masks, per-class
toggles, the scene's rain / night flags, and, on hover or click, a voxel's
classes and the probability the model gave its class. ``--info-file`` shows
the samples of another info file (this library's, or one of mmdet3d's v2
info files, as ``demo/occ_demo.py`` takes them), unlabelled.

Needs three.js and esbuild in ``node_modules/`` (``bash
tools/misc/setup_browser.sh``); see docs/visualization.md.
"""
import argparse
import os.path as osp
import sys
import tempfile
import time

from mmengine.config import Config
from mmengine.registry import DATASETS, init_default_scope

from projects.occ_common.apis import init_model
from projects.occ_common.apis.browse_samples import (BrowseSamples,
                                                     label_settings,
                                                     with_point_labels)
from projects.occ_common.apis.unlabelled_pipeline import \
    unlabelled_test_dataset
from projects.occ_common.datasets.single_sample import sample_info_file
from projects.occ_common.engine.config_checks import (CfgOptionsAction,
                                                      apply_cfg_options,
                                                      cfg_errors_exit)
from projects.occ_common.fileio.safe_pickle import RefusedGlobalError
from projects.occ_common.visualization.web import (ViewerAssetsMissing,
                                                   ViewerServer, export_html,
                                                   viewer_meta, viewer_script)


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(
        description=__doc__.split('\n')[0],
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('config', help='config file')
    preds = parser.add_mutually_exclusive_group()
    preds.add_argument('--checkpoint', help='predict with this checkpoint')
    preds.add_argument(
        '--pred-dir',
        help='read predictions from this tools/test.py --format-only folder')
    parser.add_argument(
        '--info-file',
        help="show this info file's samples instead of the config's test "
        "split (this library's or an mmdet3d v2 info file), unlabelled")
    parser.add_argument(
        '--data-root',
        help="root of --info-file's paths (default: its folder)")
    parser.add_argument(
        '--sample-idx', type=int, nargs='+', default=[0],
        help='sample(s) to export, or the first one the server shows')
    parser.add_argument(
        '--export-html', help='write one self-contained HTML file and exit')
    parser.add_argument('--port', type=int, default=8765)
    parser.add_argument(
        '--host', default='127.0.0.1',
        help='address to bind (default: this machine only; reach it over '
        'SSH port forwarding)')
    parser.add_argument('--device', default='cpu', help='e.g. cuda:0, cpu')
    parser.add_argument(
        '--no-prob', action='store_true',
        help="skip the model's second (logits) pass: no probabilities")
    parser.add_argument(
        '--all-sweeps', action='store_true',
        help='draw the merged sweeps too, not only the key frame points')
    parser.add_argument(
        '--max-points', type=int,
        help='draw at most this many LiDAR points per sample')
    parser.add_argument(
        '--allow-key-mismatch', action='store_true',
        help='use a checkpoint whose keys or shapes differ from the model')
    parser.add_argument(
        '--cfg-options', nargs='+', action=CfgOptionsAction,
        help='config overrides key=value (checked as in tools/test.py)')
    return parser.parse_args(argv)


def build_samples(args, tmp: str) -> BrowseSamples:
    """The dataset (and model) of the command line.

    Raises:
        FileNotFoundError, ValueError, RefusedGlobalError: Bad input,
            naming the file.
    """
    if not osp.isfile(args.config):
        raise FileNotFoundError(f'config not found: {args.config}')
    cfg = Config.fromfile(args.config)
    apply_cfg_options(cfg, args)
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    if args.info_file is not None:
        data_root = args.data_root or osp.dirname(osp.abspath(
            args.info_file))
        # An mmdet3d info file: only the chosen sample is converted.
        picked = sample_info_file(args.info_file, data_root, tmp,
                                  args.sample_idx[0])
        dataset = unlabelled_test_dataset(cfg, picked.info_file, data_root)
        if picked.source == 'mmdet3d':
            args.sample_idx = [0]  # the converted file's one sample
    else:
        dataset = DATASETS.build(
            with_point_labels(cfg.test_dataloader.dataset))
    model = None
    if args.checkpoint is not None:
        # Options merged above already: the config goes in as it is.
        model = init_model(cfg, args.checkpoint, args.device,
                           allow_key_mismatch=args.allow_key_mismatch)
    convention, class_names, empty = label_settings(cfg)
    return BrowseSamples(dataset, convention, class_names, empty,
                         model=model, pred_dir=args.pred_dir,
                         with_prob=not args.no_prob,
                         all_sweeps=args.all_sweeps,
                         max_points=args.max_points)


def check_indices(indices, count: int, where: str) -> None:
    """Refuse a sample index outside the dataset."""
    for index in indices:
        if not 0 <= index < count:
            raise ValueError(f'--sample-idx {index} is outside {where} '
                             f'({count} samples: 0..{count - 1})')


def main(argv=None):
    """Serve the viewer (until Ctrl-C) or write the export; returns the
    export's sizes or the stopped server."""
    args = parse_args(argv)
    title = f'{osp.basename(args.config)}'
    with tempfile.TemporaryDirectory() as tmp:
        try:
            with cfg_errors_exit():
                samples = build_samples(args, tmp)
            check_indices(args.sample_idx, len(samples),
                          args.info_file or args.config)
            script = viewer_script()
        except (FileNotFoundError, ValueError, RefusedGlobalError,
                ViewerAssetsMissing) as err:
            sys.exit(f'browse_occ.py: error: {err}')
        meta = viewer_meta(samples.class_names, samples.empty_label,
                           len(samples), title=title,
                           initial_index=args.sample_idx[0])
        if args.export_html:
            encoded = [samples.encode(i) for i in args.sample_idx]
            sizes = export_html(
                args.export_html, meta, encoded, script, title,
                note=f'tools/misc/browse_occ.py {args.config} samples '
                f'{args.sample_idx} ({time.strftime("%Y-%m-%d")})')
            print(f'wrote {args.export_html} ({sizes["file"] / 1e6:.2f} MB)')
            return sizes
        server = ViewerServer(meta, samples.encode, script, args.host,
                              args.port, title=title, quiet=False)
        print(f'serving {len(samples)} samples of {args.config} at '
              f'{server.url}\nfrom a laptop: ssh -N -L {args.port}:'
              f'localhost:{args.port} USER@THIS_HOST, then open '
              f'http://localhost:{args.port}  (Ctrl-C stops)', flush=True)
        try:
            server.serve_forever()
        except KeyboardInterrupt:
            pass
        finally:
            server.server_close()
        return server


if __name__ == '__main__':
    main()
