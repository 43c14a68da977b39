"""Predict the occupancy of one sample and draw it (mmdet3d's ``demo/``).

Usage::

    python demo/occ_demo.py CONFIG CHECKPOINT INFO_FILE \\
        [--sample-idx N | --sample-token TOKEN] [--data-root DIR] \\
        --out-dir DIR [--device cuda:0|cpu] [--cfg-options KEY=VALUE ...]

    # a key frame of mmdet3d's own nuScenes val infos
    python demo/occ_demo.py \\
        configs/occ_cyl/occcyl_r50-swins_3xb1-24e_surroundocc-nus.py \\
        occcyl.pth \\
        data/nuscenes/nuscenes_infos_val.pkl --data-root data/nuscenes \\
        --sample-idx 0 --out-dir outputs

``INFO_FILE`` is an info file of ``tools/create_data.py`` or one of
mmdet3d's v2 info files (``nuscenes_infos_val.pkl``; its chosen sample is
converted as ``create_data.py --from-mmdet3d-info`` converts it, see
``projects/occ_common/datasets/single_sample.py``); its paths are relative
to ``--data-root`` (default: the info file's folder). The sample needs no
labels: the config's test pipeline runs as ``tools/test.py --format-only``
runs it (``LoadOccupancyGT(allow_unlabelled=True)``, no lidarseg steps).

Writes, named after the sample token, ``<out-dir>/<token>.npz`` (the
predicted labels, uint8, as ``semantics``, ``arr_0`` and ``pred``: the
Occ3D file of ``tools/test.py --format-only``) and
``<out-dir>/<token>.png`` (the picture of ``OccLocalVisualizer``: the
cameras with the occupancy projected, top-down and 3D), and prints one
line per file.

As in mmdet3d's ``init_model`` / ``inference_multi_modality_detector``,
the model is built from the config and the sample goes through the
config's test pipeline and the model's ``test_step``; unlike them, the
info file and the checkpoint are read with the restricted unpicklers
(nothing in them can run code), and a checkpoint whose keys or shapes
differ from the model's, or that holds NaN / inf, is refused, as
``tools/test.py`` refuses it. Bad input ends with one line naming the file
or sample and what was expected.
"""
import argparse
import os.path as osp
import sys
import tempfile

import torch
from mmdet3d.registry import VISUALIZERS
from mmengine.config import Config
from mmengine.dataset import pseudo_collate
from mmengine.registry import init_default_scope

from projects.occ_common.apis import init_model
from projects.occ_common.apis.unlabelled_pipeline import \
    unlabelled_test_dataset
from projects.occ_common.datasets.single_sample import (SampleInfo,
                                                        sample_info_file)
from projects.occ_common.engine.config_checks import (CfgOptionsAction,
                                                      apply_cfg_options)
from projects.occ_common.evaluation.occupancy_export import \
    write_occ3d_prediction
from projects.occ_common.fileio.safe_pickle import RefusedGlobalError


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(
        description='Predict and draw the occupancy of one sample')
    parser.add_argument('config', help='config file')
    parser.add_argument('checkpoint', help='checkpoint file')
    parser.add_argument(
        'info_file',
        help='info file of tools/create_data.py or an mmdet3d v2 info file')
    which = parser.add_mutually_exclusive_group()
    which.add_argument(
        '--sample-idx', type=int, help='index of the sample (default 0)')
    which.add_argument('--sample-token', help='nuScenes token of the sample')
    parser.add_argument(
        '--data-root',
        help="root the info file's paths are relative to (default: the "
        "info file's folder)")
    parser.add_argument(
        '--out-dir', required=True, help='folder of the written files')
    parser.add_argument(
        '--device',
        default='cuda:0' if torch.cuda.is_available() else 'cpu',
        help='device of the model (default: cuda:0 when available, '
        'else cpu)')
    parser.add_argument(
        '--cfg-options',
        nargs='+',
        action=CfgOptionsAction,
        help='override config settings, KEY=VALUE items as in '
        'tools/test.py')
    return parser.parse_args(argv)


def load_config(args) -> Config:
    """The config with ``--cfg-options`` checked and merged.

    Raises:
        FileNotFoundError: The config does not exist.
        ValueError: An override of the wrong kind, or a typo of a Runner
            key (``config_checks``).
    """
    if not osp.isfile(args.config):
        raise FileNotFoundError(f'config not found: {args.config}')
    cfg = Config.fromfile(args.config)  # imports its custom_imports
    apply_cfg_options(cfg, args)
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    return cfg


def check_sample_files(dataset, sample: SampleInfo, info_file: str) -> None:
    """Refuse a sample whose key frame or camera image is missing.

    Raises:
        FileNotFoundError: Naming the info file, the sample and the path.
    """
    info = dataset.get_data_info(sample.index)
    where = f'{info_file}: sample {sample.token}'
    files = [('LiDAR key frame', info['lidar_path'])]
    files += [(f'{cam} image', image['img_path'])
              for cam, image in info['images'].items()]
    for what, path in files:
        if not osp.isfile(path):
            raise FileNotFoundError(
                f'{where}: {what} not found: {path} (check --data-root)')


def inference_occupancy(model, dataset, index: int):
    """Run the sample through the pipeline and the model.

    Args:
        model (nn.Module): From
            :func:`~projects.occ_common.apis.init_model`.
        dataset (BaseDataset): From
            :func:`~projects.occ_common.apis.unlabelled_pipeline.unlabelled_test_dataset`.
        index (int): The sample's index.

    Returns:
        tuple: The packed sample (``inputs``: ``img`` Shape (N, 3, H, W),
        ``points``) and the output data sample on the CPU, ``pred_occ``
        Shape (X, Y, Z).
    """
    packed = dataset[index]
    with torch.no_grad():
        output = model.test_step(pseudo_collate([packed]))[0]
    return packed, output.cpu()


def draw(cfg: Config, dataset, packed: dict, output, path: str) -> str:
    """Write the picture of ``OccLocalVisualizer`` (the config's
    visualiser), as ``tools/test.py --show-dir`` draws it."""
    vis_cfg = dict(cfg.get('visualizer', None)
                   or dict(type='OccLocalVisualizer'))
    # Only the file: no backend folder.
    vis_cfg.update(name='occ_demo', vis_backends=None, save_dir=None)
    visualizer = VISUALIZERS.build(vis_cfg)
    visualizer.dataset_meta = dataset.metainfo
    visualizer.add_datasample(
        osp.splitext(osp.basename(path))[0],
        data_input=packed['inputs'],
        data_sample=output,
        draw_gt=False,
        out_file=path)
    return path


def main(argv=None):
    """Predict, write and draw one sample; print the written files."""
    args = parse_args(argv)
    data_root = args.data_root or osp.dirname(osp.abspath(args.info_file))
    with tempfile.TemporaryDirectory() as tmp:
        try:
            cfg = load_config(args)
            sample = sample_info_file(
                args.info_file, data_root, tmp, args.sample_idx,
                args.sample_token)
            dataset = unlabelled_test_dataset(cfg, sample.info_file,
                                              data_root)
            check_sample_files(dataset, sample, args.info_file)
            model = init_model(cfg, args.checkpoint, args.device)
        except (FileNotFoundError, ValueError, RefusedGlobalError) as err:
            sys.exit(f'occ_demo.py: error: {err}')
        packed, output = inference_occupancy(model, dataset, sample.index)
    # Both named by the token, checked by sample_info_file (and again by
    # write_occ3d_prediction): nothing is written outside --out-dir.
    prediction = write_occ3d_prediction(args.out_dir, sample.token,
                                        output.pred_occ)
    written = [
        prediction,
        draw(cfg, dataset, packed, output,
             osp.splitext(prediction)[0] + '.png')
    ]
    for kind, path in zip(('prediction', 'picture'), written):
        print(f'{kind}: {path}')
    return written


if __name__ == '__main__':
    main()  # every refusal, a wrong --cfg-options too, ends in one line
