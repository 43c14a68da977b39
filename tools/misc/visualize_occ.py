#!/usr/bin/env python
"""Render occupancy grids to a PNG, without a display.

Two sources:

- a model: ``--config C --checkpoint K --index I`` predicts sample ``I`` of
  the config's test split and draws prediction, GT and error map
  (``--cameras`` adds the six images with the occupancy projected onto
  them; ``--save-pred F.npz`` also stores the grids);
- saved grids: ``--pred F`` and / or ``--gt F``, each an ``.npz`` (keys
  ``pred_occ`` / ``gt_occ`` / ``mask_camera``, with the label
  ``convention`` and ``class_names``, as ``--save-pred`` writes them;
  Occ3D's ``labels.npz`` with ``semantics`` and ``mask_camera``; an Occ3D
  submission file of ``tools/test.py --format-only`` or the
  challenge's ``<token>.npz``; FlashOcc's ``pred.npz`` with ``pred``, whose
  pickled ``gt`` is never loaded; these imply ``--convention occ3d``) or an
  ``.npy`` (a dense (X, Y, Z) grid, or SurroundOcc's sparse (N, 4) ``x, y,
  z, label`` rows of a label or a ``--format-only`` prediction, which need
  ``--occ-shape``).

Examples::

    python tools/misc/visualize_occ.py --config CFG --checkpoint CKPT \\
        --index 0 --out sample0.png
    python tools/misc/visualize_occ.py --pred sample0.npz --out sample0.png
    python tools/misc/visualize_occ.py --gt data/gts/scene/token/labels.npz \\
        --convention occ3d --out gt.png
    python tools/misc/visualize_occ.py --pred old.npz --config CFG --out p.png

The labels of saved grids follow, in this order: ``--convention`` /
``--class-names``, the file's own (``--save-pred`` stores them), the
metric of ``--config`` given without ``--checkpoint``, the file layout's
(Occ3D's files), else SurroundOcc's; labels that do not fit end the tool
with one line naming the flag to pass.

Unlike the train and test tools this script imports the plugin's renderer
directly: it draws grids that need no config.
"""
import argparse
import os.path as osp
import sys
from typing import Dict, Optional, Sequence

import numpy as np
import torch

from projects.occ_common.engine.config_checks import (CfgOptionsAction,
                                                      cfg_errors_exit)
from projects.occ_common.visualization import (convention_classes,
                                               render_data_sample,
                                               sample_field, save_png)


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', required=True, help='output PNG file')
    model = parser.add_argument_group('from a model')
    model.add_argument(
        '--config',
        help='config file (with --pred / --gt and no --checkpoint: only '
        'its label convention and class names are read)')
    model.add_argument('--checkpoint', help='checkpoint file')
    model.add_argument(
        '--index', type=int, default=0, help='sample index in the test set')
    model.add_argument(
        '--cameras',
        action='store_true',
        help='add the camera images with the occupancy projected onto them')
    model.add_argument(
        '--save-pred', help='also store pred / GT / mask in this .npz')
    model.add_argument('--device', default='cpu', help='e.g. cpu, cuda:0')
    model.add_argument(
        '--allow-key-mismatch',
        action='store_true',
        help='draw with a checkpoint whose keys or shapes differ from the '
        "model's (missing ones keep their initialisation); refused by "
        'default')
    model.add_argument(
        '--cfg-options',
        nargs='+',
        action=CfgOptionsAction,
        help='config overrides key=value (checked as in tools/test.py)')
    saved = parser.add_argument_group('from saved grids')
    saved.add_argument('--pred', help='.npz / .npy predicted grid')
    saved.add_argument('--gt', help='.npz / .npy ground-truth grid')
    saved.add_argument(
        '--occ-shape',
        '--grid-shape',  # its former name
        dest='occ_shape',
        type=int,
        nargs=3,
        default=(200, 200, 16),
        help='occupancy grid (X, Y, Z) of sparse SurroundOcc .npy files')
    labels = parser.add_argument_group('labels (from the config if given)')
    labels.add_argument(
        '--convention',
        choices=['surroundocc', 'occ3d'],
        help='label convention (default: the config\'s metric, else '
        'surroundocc)')
    labels.add_argument(
        '--class-names', nargs='+', help='class names in label order')
    view = parser.add_argument_group('view')
    view.add_argument('--azimuth', type=float, default=-150.0)
    view.add_argument('--elevation', type=float, default=40.0)
    view.add_argument(
        '--forward',
        choices=['+x', '+y', '-x', '-y'],
        help='grid direction ahead of the car, drawn up in the top-down '
        "views (default: the sample's lidar2ego, else +x for occ3d and +y "
        "for surroundocc, whose grids are in nuScenes' LiDAR frame)")
    view.add_argument(
        '--view-size', type=int, nargs=2, default=(360, 480),
        help='(H, W) of the 3D views')
    args = parser.parse_args(argv)
    saved_grids = args.pred is not None or args.gt is not None
    if args.checkpoint is not None and args.config is None:
        parser.error('--checkpoint needs --config.')
    if args.checkpoint is not None and saved_grids:
        parser.error('give either --config/--checkpoint or --pred/--gt.')
    if args.checkpoint is None and not saved_grids:
        parser.error('give --config/--checkpoint, or --pred/--gt (with an '
                     'optional --config for the labels).')
    return args


#: Keys of the one grid of a foreign ``.npz``, in the order they are looked
#: for, and the convention each implies: Occ3D's ``labels.npz``
#: (``semantics``), an Occ3D submission file (``semantics`` and / or the
#: unnamed ``arr_0``), FlashOcc's ``pred.npz`` (``pred``).
FOREIGN_KEYS = {'semantics': 'occ3d', 'arr_0': 'occ3d', 'pred': 'occ3d'}


def load_grid(path: str, key: str,
              occ_shape: Sequence[int]) -> Dict[str, np.ndarray]:
    """Read a saved grid (see the module docstring).

    Nothing pickled is ever loaded: FlashOcc's ``pred.npz`` also stores its
    GT as a pickled object (``gt``), which is skipped; give the Occ3D
    ``labels.npz`` as ``--gt`` instead.

    Args:
        path (str): ``.npz`` or ``.npy`` file.
        key (str): ``'pred_occ'`` or ``'gt_occ'``: which grid the file is
            given for.
        occ_shape (Sequence[int]): ``(X, Y, Z)`` of a sparse SurroundOcc
            file.

    Returns:
        dict[str, np.ndarray]: ``key`` and whatever else the file holds of
        ``pred_occ``, ``gt_occ`` and ``mask_camera``; ``'convention'``
        (a str) when the file's layout implies one.

    Raises:
        ValueError: If the file holds no usable grid.
    """
    if path.endswith('.npz'):
        with np.load(path, allow_pickle=False) as data:
            names = list(data.files)
            wanted = ['pred_occ', 'gt_occ', 'mask_camera', 'convention',
                      'class_names'] + list(FOREIGN_KEYS)
            found = {}
            for name in wanted:
                if name in names:
                    try:
                        found[name] = data[name]
                    except ValueError:  # a pickled object: never loaded
                        continue
        grids = {
            k: found[k]
            for k in ('pred_occ', 'gt_occ', 'mask_camera') if k in found
        }
        # Written by --save-pred: the labels' own convention and names.
        if 'convention' in found:
            grids['convention'] = str(found['convention'])
        if 'class_names' in found:
            grids['class_names'] = [str(n) for n in found['class_names']]
        if key not in grids:
            # FlashOcc's 'pred' is a prediction, never a GT.
            foreign = [
                k for k in FOREIGN_KEYS
                if k in found and (k != 'pred' or key == 'pred_occ')
            ]
            if not foreign:
                raise ValueError(
                    f'{path}: expected an array {key!r}, Occ3D '
                    "'semantics' / 'arr_0' or (a prediction) FlashOcc "
                    f"'pred', found {names}.")
            grids[key] = found[foreign[0]]
            grids['convention'] = FOREIGN_KEYS[foreign[0]]
        return grids
    if not path.endswith('.npy'):
        raise ValueError(f'{path}: expected a .npz or .npy file.')
    array = np.load(path, allow_pickle=False)
    if array.ndim == 2 and array.shape[1] == 4:
        return {key: sparse_to_dense(array, occ_shape, path)}
    if array.ndim != 3:
        raise ValueError(f'{path}: expected a dense (X, Y, Z) grid or '
                         f'sparse (N, 4) rows, got shape {array.shape}.')
    return {key: array}


def sparse_to_dense(rows: np.ndarray, occ_shape: Sequence[int],
                    path: str) -> np.ndarray:
    """SurroundOcc's ``x, y, z, label`` rows as a dense grid (0 = empty).

    Raises:
        ValueError: If an index lies outside ``occ_shape``.
    """
    rows = rows.astype(np.int64)
    shape = np.asarray(occ_shape)
    outside = (rows[:, :3] < 0).any(1) | (rows[:, :3] >= shape).any(1)
    if outside.any():
        raise ValueError(f'{path}: voxel {rows[outside][0, :3].tolist()} is '
                         f'outside --occ-shape {tuple(occ_shape)}.')
    dense = np.zeros(tuple(occ_shape), dtype=np.int64)
    dense[rows[:, 0], rows[:, 1], rows[:, 2]] = rows[:, 3]
    return dense


def check_label_range(sample: Dict, class_names: Sequence[str],
                      convention: str, path: str) -> None:
    """End the tool in one line when saved labels exceed the classes.

    A grid saved from an Occ3D config (18 classes, free = 17) drawn with
    SurroundOcc's 17 classes ended in a traceback deep in the renderer.

    Raises:
        SystemExit: Code 2, naming the file, the labels and the flags.
    """
    for key in ('pred_occ', 'gt_occ'):
        grid = sample.get(key)
        if grid is None:
            continue
        labels = np.unique(np.asarray(grid))
        bad = labels[(labels < 0) | ((labels >= len(class_names))
                                     & (labels != 255))]
        if bad.size:
            sys.stderr.write(
                f'visualize_occ.py: error: {path}: {key} holds labels '
                f'{bad.tolist()[:5]}, outside the {len(class_names)} classes '
                f'of the {convention!r} convention; pass --convention occ3d '
                '(or --config CONFIG, or --class-names) to say what they '
                'are.\n')
            raise SystemExit(2)


def metric_labels(cfg) -> Dict:
    """``convention`` / ``class_names`` of the config's test metric."""
    evaluator = cfg.get('test_evaluator', {})
    metrics = evaluator if isinstance(evaluator, list) else [evaluator]
    for metric in metrics:
        if 'convention' in metric or 'class_names' in metric:
            return {
                k: metric[k]
                for k in ('convention', 'class_names') if k in metric
            }
    return {}


def predict_sample(args):
    """Predict ``args.index`` of the config's test set.

    Returns:
        tuple: The output data sample, the packed inputs of the sample,
        and the label settings of the config's metric.
    """
    from mmengine.dataset import pseudo_collate
    from mmengine.registry import DATASETS

    from projects.occ_common.apis import init_model

    model = init_model(args.config, args.checkpoint, args.device,
                       args.cfg_options,
                       getattr(args, 'cfg_options_raw', None),
                       args.allow_key_mismatch)
    cfg = model.cfg
    dataset = DATASETS.build(cfg.test_dataloader.dataset)
    if not 0 <= args.index < len(dataset):
        raise ValueError(f'--index {args.index} is outside the test set of '
                         f'{args.config} ({len(dataset)} samples).')
    data = pseudo_collate([dataset[args.index]])
    with torch.no_grad():
        sample = model.test_step(data)[0]
    return sample, data['inputs'], metric_labels(cfg)


def main(argv=None) -> Optional[str]:
    """Render and write the picture; returns the output path."""
    args = parse_args(argv)
    labels: Dict = {}
    img = None
    if args.checkpoint is not None:
        with cfg_errors_exit():
            sample, inputs, labels = predict_sample(args)
        if args.cameras:
            if not isinstance(inputs, dict) or inputs.get('img') is None:
                raise ValueError(f'--cameras: the test samples of '
                                 f'{args.config} carry no images.')
            img = inputs['img'][0]
    else:
        sample = {}
        if args.gt is not None:
            sample.update(load_grid(args.gt, 'gt_occ', args.occ_shape))
        if args.pred is not None:
            sample.update(load_grid(args.pred, 'pred_occ', args.occ_shape))
        name = osp.splitext(osp.basename(args.pred or args.gt))[0]
        sample['sample_idx'] = name
        for key in ('convention', 'class_names'):
            if key in sample:
                labels.setdefault(key, sample.pop(key))
        if args.config is not None:
            from mmengine.config import Config
            for key, value in metric_labels(
                    Config.fromfile(args.config)).items():
                labels.setdefault(key, value)
    convention = args.convention or labels.get('convention', 'surroundocc')
    if isinstance(sample, dict):
        # Saved grids carry no lidar2ego: their convention's frame says
        # which way is ahead.
        sample.setdefault('occ_format', convention)
    view = {} if args.forward is None else dict(forward=args.forward)
    default_names, empty_label = convention_classes(convention)
    class_names = (args.class_names or labels.get('class_names')
                   or default_names)
    if args.checkpoint is None:
        check_label_range(sample, class_names, convention,
                          args.pred or args.gt)
    if args.save_pred:
        arrays = {}
        for key in ('pred_occ', 'gt_occ', 'mask_camera'):
            value = sample_field(sample, key)
            if torch.is_tensor(value):
                value = value.cpu().numpy()
            if value is not None:
                arrays[key] = np.asarray(value)
        # Plain string arrays (no pickle): the file says what its labels
        # are, so that --pred FILE draws it without further flags.
        np.savez_compressed(args.save_pred, **arrays,
                            convention=np.array(convention),
                            class_names=np.array(list(class_names)))
    picture = render_data_sample(
        sample,
        class_names,
        empty_label,
        img=img,
        azimuth=args.azimuth,
        elevation=args.elevation,
        view_size=tuple(args.view_size),
        **view)
    save_png(picture, args.out)
    print(f'wrote {args.out}')
    return args.out


if __name__ == '__main__':
    main()
