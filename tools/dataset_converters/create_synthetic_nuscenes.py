"""Write a small synthetic nuScenes-format world (with lidarseg, SurroundOcc
and Occ3D occupancy labels) for demos and tests.

    python tools/dataset_converters/create_synthetic_nuscenes.py \\
        data/nuscenes_synthetic \\
        --scenes 2 --samples 4 --sweeps 10 --image-size 480 270 --seed 0
    # four cameras and a LiDAR without ring index (docs/customize_dataset.md)
    python tools/dataset_converters/create_synthetic_nuscenes.py \
        data/nuscenes_synthetic_quad --camera-rig quad --no-lidar-ring

See ``projects/occ_common/synthetic/generate.py`` for the layout.
"""
import argparse
import json

from projects.occ_common.synthetic import (CAMERA_RIGS, CONDITIONS,
                                           generate_synthetic_nuscenes)


def parse_args(argv=None):
    """Parses the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('out_dir', help='dataset root to write')
    parser.add_argument('--scenes', type=int, default=2,
                        help='number of scenes (default 2)')
    parser.add_argument('--samples', type=int, default=4,
                        help='key frames per scene (default 4)')
    parser.add_argument('--sweeps', type=int, default=10,
                        help='LiDAR sweeps per key-frame interval '
                        '(default 10: 20 Hz LiDAR, 2 Hz key frames)')
    parser.add_argument('--image-size', type=int, nargs=2, default=[480, 270],
                        metavar=('W', 'H'), help='camera image size '
                        '(default 480 270)')
    parser.add_argument('--version', default='v1.0-mini',
                        help='table folder name (default v1.0-mini)')
    parser.add_argument('--seed', type=int, default=0, help='random seed')
    parser.add_argument('--azimuth-bins', type=int, default=512,
                        help='LiDAR azimuth steps per revolution '
                        '(default 512)')
    parser.add_argument('--conditions', nargs='+', choices=sorted(CONDITIONS),
                        help='one weather / time of day per scene (default: '
                        'clear, night_rain, rain, night, ...)')
    parser.add_argument('--camera-rig', choices=sorted(CAMERA_RIGS),
                        default='nuscenes', help='nuscenes: the six nuScenes '
                        'cameras (default); quad: four wide cameras')
    parser.add_argument('--no-lidar-ring', dest='lidar_ring',
                        action='store_false', help='write x, y, z, '
                        'intensity per LiDAR point (no ring index)')
    parser.add_argument('--overwrite', action='store_true',
                        help='replace an earlier synthetic world in OUT_DIR')
    return parser.parse_args(argv)


def main(argv=None):
    """Generates the world and prints its summary."""
    args = parse_args(argv)
    summary = generate_synthetic_nuscenes(
        args.out_dir, num_scenes=args.scenes,
        samples_per_scene=args.samples, sweeps_per_sample=args.sweeps,
        image_size=tuple(args.image_size), version=args.version,
        seed=args.seed, overwrite=args.overwrite,
        azimuth_bins=args.azimuth_bins, conditions=args.conditions,
        camera_rig=args.camera_rig, lidar_ring=args.lidar_ring,
        progress=True)
    brief = {k: v for k, v in summary.items()
             if k not in ('paths', 'sample_tokens')}
    print(json.dumps(brief, indent=1))


if __name__ == '__main__':
    main()
