"""Create the occupancy info files of a nuScenes root (real or synthetic).

Usage (mmdet3d 1.x ``tools/create_data.py`` style)::

    # real nuScenes with SurroundOcc labels in data/nuscenes/nuscenes_occ
    # and Occ3D labels in data/nuscenes/gts
    python tools/create_data.py nuscenes --root-path data/nuscenes \\
        --version v1.0-trainval --max-sweeps 10
    # a synthetic world (tools/dataset_converters/create_synthetic_nuscenes.py)
    python tools/create_data.py nuscenes --root-path data/synthetic_nuscenes \\
        --version v1.0-mini
    # mmdet3d's own info files, extended with the occupancy label paths
    python tools/create_data.py nuscenes --root-path data/nuscenes \\
        --from-mmdet3d-info data/nuscenes/nuscenes_infos_val.pkl

Writes ``<out-dir>/<extra-tag>_infos_{train,val,val_rainy,val_night}.pkl``
(``v1.0-test``: ``_infos_test.pkl``; ``v1.0``, mmdet3d's default: both);
existing files are kept unless ``--overwrite``. ``--from-mmdet3d-info``
writes ``<extra-tag>_infos_<split>.pkl`` per given file instead. Problems
that leave the rest usable (missing sweeps, a missing label file, a
``panoptic.json`` without its files) are reported at the end, not fatal.
The conversion itself lives in
``projects/occ_common/datasets/converters/``.
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
        help='nuScenes version (v1.0-trainval, v1.0-mini, v1.0-test; '
        'v1.0 = v1.0-trainval then v1.0-test, as in mmdet3d)')
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
    parser.add_argument(
        '--workers',
        type=int,
        default=4,
        help='processes that convert samples (0: this one)')
    parser.add_argument(
        '--num-pts-feats',
        type=int,
        help='float32 values per point of the LiDAR files (default: a '
        'synthetic world\'s own, else nuScenes\' 5: x, y, z, intensity, '
        'ring); e.g. 4 for x, y, z, intensity')
    parser.add_argument(
        '--from-mmdet3d-info',
        nargs='+',
        metavar='INFO_FILE',
        help='extend these mmdet3d v2 info files with the occupancy label '
        'paths instead of converting the nuScenes tables')
    return parser.parse_args(argv)


def main(argv=None):
    """Run the converter and print the written files."""
    args = parse_args(argv)
    from projects.occ_common.datasets.converters import (
        extend_mmdet3d_infos, nuscenes_occ_converter)
    labels = dict(
        surroundocc_root=args.surroundocc_root, occ3d_root=args.occ3d_root)
    written = {}
    if args.from_mmdet3d_info:
        for info_file in args.from_mmdet3d_info:
            split, path = extend_mmdet3d_infos.extend_mmdet3d_info_file(
                info_file,
                args.root_path,
                out_dir=args.out_dir,
                info_prefix=args.extra_tag,
                overwrite=args.overwrite,
                **labels)
            written[split] = path
    else:
        # mmdet3d's v1.0 is the trainval release and its test release.
        versions = ['v1.0-trainval', 'v1.0-test'] \
            if args.version == 'v1.0' else [args.version]
        for version in versions:
            written.update(
                nuscenes_occ_converter.create_nuscenes_occ_infos(
                    args.root_path,
                    out_dir=args.out_dir,
                    info_prefix=args.extra_tag,
                    version=version,
                    max_sweeps=args.max_sweeps,
                    val_scenes=args.val_scenes,
                    overwrite=args.overwrite,
                    workers=args.workers,
                    num_pts_feats=args.num_pts_feats,
                    **labels))
    for split, path in written.items():
        print(f'{split}: {path}')
    return written


if __name__ == '__main__':
    main()
