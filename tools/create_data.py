"""Create the occupancy info files of a nuScenes root (real or synthetic).

Usage (mmdet3d 1.x ``tools/create_data.py`` style)::

    # real nuScenes with SurroundOcc labels in data/nuscenes/nuscenes_occ
    # and Occ3D labels in data/nuscenes/gts
    python tools/create_data.py nuscenes --root-path data/nuscenes \\
        --version v1.0-trainval --max-sweeps 10
    # a synthetic world (tools/create_synthetic_nuscenes.py)
    python tools/create_data.py nuscenes --root-path data/synthetic_nuscenes \\
        --version v1.0-mini

Writes ``<out-dir>/<extra-tag>_infos_{train,val,val_rainy,val_night}.pkl``
(``v1.0-test``: ``_infos_test.pkl``); existing files are kept unless
``--overwrite``. The conversion itself lives in
``projects/occ_common/datasets/converters/nuscenes_occ_converter.py``.
"""
import argparse


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(
        description='Create info files for occupancy prediction')
    parser.add_argument('dataset', choices=['nuscenes'], help='dataset kind')
    parser.add_argument(
        '--root-path', required=True, help='nuScenes data root')
    parser.add_argument(
        '--version',
        default='v1.0-trainval',
        help='nuScenes version (v1.0-trainval, v1.0-mini, v1.0-test)')
    parser.add_argument(
        '--out-dir', help='where the info files go (default: root path)')
    parser.add_argument(
        '--extra-tag', default='nuscenes_occ', help='info file prefix')
    parser.add_argument(
        '--max-sweeps',
        type=int,
        default=10,
        help='earlier LiDAR sweeps linked per sample')
    parser.add_argument(
        '--surroundocc-root',
        help='SurroundOcc label folder (default: <root>/nuscenes_occ)')
    parser.add_argument(
        '--occ3d-root', help='Occ3D label folder (default: <root>/gts)')
    parser.add_argument(
        '--val-scenes',
        nargs='+',
        help='scene names of the val split (default: the official split; '
        'for a synthetic world the last fifth of the scenes)')
    parser.add_argument(
        '--overwrite',
        action='store_true',
        help='replace existing info files')
    return parser.parse_args(argv)


def main(argv=None):
    """Run the converter and print the written files."""
    args = parse_args(argv)
    from projects.occ_common.datasets.converters import nuscenes_occ_converter
    written = nuscenes_occ_converter.create_nuscenes_occ_infos(
        args.root_path,
        out_dir=args.out_dir,
        info_prefix=args.extra_tag,
        version=args.version,
        surroundocc_root=args.surroundocc_root,
        occ3d_root=args.occ3d_root,
        max_sweeps=args.max_sweeps,
        val_scenes=args.val_scenes,
        overwrite=args.overwrite)
    for split, path in written.items():
        print(f'{split}: {path}')
    return written


if __name__ == '__main__':
    main()
