"""Make Occ3D and SurroundOcc occupancy labels from a nuScenes-format
dataset's LiDAR sequences.

    python tools/dataset_converters/generate_occupancy.py \\
        --root-path data/my_nuscenes --version v1.0-trainval \\
        --out-dir data/my_nuscenes/generated_occ --workers 4
    # then link them into the info files:
    python tools/create_data.py nuscenes --root-path data/my_nuscenes \\
        --version v1.0-trainval \\
        --occ3d-root data/my_nuscenes/generated_occ/gts \\
        --surroundocc-root data/my_nuscenes/generated_occ/nuscenes_occ

Reads the nuScenes tables (key frames and sweeps, ego poses,
calibrations, 3D boxes with instance tokens), the LiDAR ``.pcd.bin``
files and lidarseg labels where there are any, and writes
``<out-dir>/gts/<scene>/<sample token>/labels.npz`` (Occ3D: semantics,
mask_lidar, mask_camera) and
``<out-dir>/nuscenes_occ/samples/<LiDAR file>.npy`` (SurroundOcc rows).
A rerun skips the scenes already finished (``<out-dir>/progress/``). The
steps and every setting's reason:
``projects/occ_common/datasets/occupancy_labels/`` and
docs/dataset_prepare.md.
"""
import argparse
import json


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--root-path', required=True,
                        help='nuScenes-format data root')
    parser.add_argument('--version', default='v1.0-trainval',
                        help='table folder (default v1.0-trainval)')
    parser.add_argument('--out-dir', required=True,
                        help='where gts/ and nuscenes_occ/ are written')
    parser.add_argument('--workers', type=int, default=0,
                        help='processes, one scene each (0: this one)')
    parser.add_argument('--scenes', nargs='+', metavar='NAME',
                        help='label only these scenes (default: all)')
    parser.add_argument('--overwrite', action='store_true',
                        help='relabel every scene, also if OUT_DIR holds '
                        'labels made with other settings')
    group = parser.add_argument_group(
        'settings (defaults: LabelConfig in '
        'projects/occ_common/datasets/occupancy_labels/config.py)')
    group.add_argument('--key-frame-only', action='store_true',
                       help='voxelise each key frame\'s own sweep as it '
                       'is, without carving or densification (a baseline, '
                       'as the quality benchmark makes it)')
    group.add_argument('--no-box-frame', action='store_true',
                       help='accumulate objects in the world frame like '
                       'the static scene (a baseline: moving objects '
                       'smear)')
    group.add_argument('--surface-depth', type=float,
                       help='voxelise each return this many voxel edges '
                       'behind its surface (default 0)')
    group.add_argument('--ground-fill-radius', type=float,
                       help='fill unobserved ground from observed ground '
                       'this many metres away at most (0: no fill; '
                       'default: unlimited)')
    group.add_argument('--no-fill-objects', action='store_true',
                       help='do not fill objects inside the hull of their '
                       'points')
    group.add_argument('--mask-sweeps', type=int,
                       help='sweeps whose rays make mask_lidar (default 10)')
    return parser.parse_args(argv)


def label_config(args):
    """The ``LabelConfig`` the options ask for."""
    from projects.occ_common.datasets.occupancy_labels import (BASELINES,
                                                               LabelConfig)
    changes = {}
    for flag, name in (('key_frame_only', 'key-frame'),
                       ('no_box_frame', 'no-box-frame')):
        if getattr(args, flag):
            changes.update(BASELINES[name])
    if args.no_fill_objects:
        changes['fill_objects'] = False
    for key in ('surface_depth', 'ground_fill_radius', 'mask_sweeps'):
        if getattr(args, key) is not None:
            changes[key] = getattr(args, key)
    return LabelConfig(**changes)


def main(argv=None):
    """Generate the labels and print a summary."""
    args = parse_args(argv)
    from projects.occ_common.datasets.occupancy_labels import \
        generate_occupancy
    summary = generate_occupancy(
        args.root_path, args.version, args.out_dir, label_config(args),
        workers=args.workers, scenes=args.scenes, overwrite=args.overwrite)
    print(json.dumps(dict(summary, out_dir=args.out_dir), indent=1))
    return summary


if __name__ == '__main__':
    main()
