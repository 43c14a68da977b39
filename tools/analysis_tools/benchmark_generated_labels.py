"""How good are generated occupancy labels? Score them against a world's
exact labels, beside two baselines.

    python tools/analysis_tools/benchmark_generated_labels.py \\
        --root-path data/nuscenes_synthetic --version v1.0-mini \\
        --out work_dirs/label_quality --workers 2

For every variant (``--variants``) labels are generated into
``OUT/<variant>/`` with ``tools/dataset_converters/generate_occupancy.py``'s
machinery (resumable: a rerun reuses finished scenes) and scored against
the labels the root already holds, file for file
(:class:`projects.occ_common.evaluation.label_quality.LabelQuality`):

* ``keyframe``: each key frame's own sweep voxelised (no accumulation,
  carving or densification);
* ``no-box-frame``: every sweep accumulated in the world frame, moving
  objects included (they smear); the other steps as ``ours``;
* ``no-densify``: ``ours`` without filling unseen ground and object
  interiors;
* ``ours``: the generator's defaults;
* ``ours-depth``: the defaults with returns voxelised a quarter voxel
  behind their surface (the exact labels' voxel convention, see
  ``LabelConfig.surface_depth``).

On a synthetic world (``tools/dataset_converters/
create_synthetic_nuscenes.py``) the root's labels are exact; on real
nuScenes they are Occ3D's / SurroundOcc's. Writes ``OUT/quality.md`` and
``OUT/quality.json``.

``--reach`` adds what bounds any label made from these sweeps: per class,
the share of the reference's occupied Occ3D voxels that some ray of the
scene reaches (crosses or ends in; every sweep's returns and no-return
rays). The rest (building interiors, the far side of things) only
densification can label.
"""
import argparse
import glob
import json
import os
import os.path as osp
import time

import numpy as np

from projects.occ_common.analysis.tool_runs import pct
from projects.occ_common.datasets.nuscenes_classes import (OCC3D_CLASS_NAMES,
                                                           OCC3D_FREE_LABEL)
from projects.occ_common.datasets.occupancy_labels import (BASELINES,
                                                           LabelConfig,
                                                           generate_occupancy,
                                                           read_scene)
from projects.occ_common.datasets.occupancy_labels.accumulation import \
    accumulate_scene
from projects.occ_common.datasets.occupancy_labels.generate import PROGRESS_DIR
from projects.occ_common.datasets.occupancy_labels.visibility import lidar_mask
from projects.occ_common.datasets.occupancy_labels.voxelization import \
    format_grid
from projects.occ_common.datasets.occupancy_labels.writers import (
    OCC3D_DIR, SURROUNDOCC_DIR)
from projects.occ_common.evaluation.label_quality import LabelQuality
from projects.occ_common.fileio.safe_names import safe_file_name

#: Variant name -> (column title, LabelConfig changes).
VARIANTS = {
    'keyframe': ('key frame alone', BASELINES['key-frame']),
    'no-box-frame': ('accumulated, no box frames', BASELINES['no-box-frame']),
    'no-densify': ('ours, no densification', dict(
        ground_fill_radius=0.0, fill_objects=False)),
    'ours': ('ours (defaults)', dict()),
    'ours-depth': ('ours, surface depth 0.25', dict(surface_depth=0.25)),
}


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--root-path', required=True,
                        help='dataset root holding the reference labels '
                        '(gts/, nuscenes_occ/)')
    parser.add_argument('--version', default='v1.0-mini')
    parser.add_argument('--out', default='work_dirs/label_quality')
    parser.add_argument('--variants', nargs='+', default=list(VARIANTS),
                        choices=list(VARIANTS))
    parser.add_argument('--scenes', nargs='+', metavar='NAME',
                        help='only these scenes (default: all)')
    parser.add_argument('--workers', type=int, default=0,
                        help='processes, one scene each (0: this one)')
    parser.add_argument('--reach', action='store_true',
                        help='also measure the share of the reference\'s '
                        'occupied voxels some ray of the scene reaches')
    return parser.parse_args(argv)


def reach(root: str, version: str, scenes=None) -> dict:
    """Per Occ3D label, the reference's occupied voxels of every key frame
    and those some ray of the scene reaches (crosses or ends in).

    Moving objects' counts mean little: rays of other sweeps cross where
    they were.

    Returns:
        dict: ``occupied`` and ``reached`` (lists over
        ``OCC3D_CLASS_NAMES``), ``share_reached`` (all labels, %).
    """
    from nuscenes import NuScenes
    cfg = LabelConfig()
    grid = format_grid('occ3d')
    num = len(OCC3D_CLASS_NAMES)
    occupied, reached = np.zeros(num, np.int64), np.zeros(num, np.int64)
    nusc = NuScenes(version, root, verbose=False)
    for scene in nusc.scene:
        if scenes and scene['name'] not in scenes:
            continue
        sequence = read_scene(nusc, scene, root)
        rays = accumulate_scene(sequence, cfg).rays
        for frame in sequence.key_frames:
            seen = lidar_mask(grid, np.linalg.inv(frame.ego2global), rays,
                              cfg.no_return_range)
            path = osp.join(root, OCC3D_DIR,
                            safe_file_name(sequence.name, 'scene name'),
                            safe_file_name(frame.token, 'sample token'),
                            'labels.npz')
            with np.load(path) as f:
                semantics = f['semantics']
            solid = semantics != OCC3D_FREE_LABEL
            occupied += np.bincount(semantics[solid], minlength=num)
            reached += np.bincount(semantics[solid & seen], minlength=num)
    return dict(occupied=occupied.tolist(), reached=reached.tolist(),
                share_reached=100 * reached.sum() / max(occupied.sum(), 1))


def score(root: str, labels_dir: str, scenes=None) -> dict:
    """Score the labels under ``labels_dir`` against ``root``'s.

    Every file the generator recorded as written (its ``progress``
    records) is scored against the reference file at the same path
    relative to ``root``.

    Returns:
        dict: :meth:`LabelQuality.summary`.
    """
    quality = LabelQuality()
    done = sorted(glob.glob(osp.join(labels_dir, PROGRESS_DIR, '*.json')))
    for marker in done:
        with open(marker) as f:
            record = json.load(f)
        if scenes and record['scene'] not in scenes:
            continue
        for rel in record['files']:
            ref = osp.join(root, rel)
            if not osp.isfile(ref):
                raise SystemExit(f'{root} has no reference label {rel} for '
                                 f'the generated {labels_dir}/{rel}.')
            if rel.startswith(OCC3D_DIR + os.sep):
                quality.add_occ3d(ref, osp.join(labels_dir, rel))
            elif rel.startswith(SURROUNDOCC_DIR + os.sep):
                quality.add_surroundocc(ref, osp.join(labels_dir, rel))
    return quality.summary()


def seconds_per_key_frame(labels_dir: str) -> float:
    """Mean generation time of a key frame (both formats and masks)."""
    seconds, frames = 0.0, 0
    for marker in glob.glob(osp.join(labels_dir, PROGRESS_DIR, '*.json')):
        with open(marker) as f:
            record = json.load(f)
        seconds += record['seconds']
        frames += record['key_frames']
    return seconds / frames if frames else float('nan')


def table(results: dict) -> str:
    """Markdown table: one column per variant."""
    names = list(results)
    lines = ['| | ' + ' | '.join(VARIANTS[n][0] for n in names) + ' |',
             '|---' * (len(names) + 1) + '|']

    def add(label, fn):
        lines.append(f'| {label} | ' + ' | '.join(
            fn(results[n]) for n in names) + ' |')

    for region, title in (('lidar_mask', 'in the exact LiDAR mask'),
                          ('camera_mask', 'in the exact camera mask'),
                          ('grid', 'whole grid')):
        add(f'Occ3D geometry IoU, {title}',
            lambda r, g=region: pct(r['occ3d'][g]['IoU']))
        add(f'**Occ3D mIoU, {title}**',
            lambda r, g=region: pct(r['occ3d'][g]['mIoU']))
    add('SurroundOcc geometry IoU (whole grid)',
        lambda r: pct(r['surroundocc']['IoU']))
    add('SurroundOcc mIoU (whole grid)',
        lambda r: pct(r['surroundocc']['mIoU']))
    for mask in ('mask_lidar', 'mask_camera'):
        add(f'{mask} IoU (recall / precision)', lambda r, m=mask: (
            f'{pct(r["masks"][m]["IoU"])} ({pct(r["masks"][m]["recall"])} '
            f'/ {pct(r["masks"][m]["precision"])})'))
    add('generation, s per key frame',
        lambda r: f'{r["seconds_per_key_frame"]:.1f}')
    for index, name in enumerate(OCC3D_CLASS_NAMES[:-1]):
        add(f'{name} (in LiDAR mask)', lambda r, i=index: pct(
            r['occ3d']['lidar_mask']['per_class'][i]))
    return '\n'.join(lines)


def main(argv=None):
    """Generate every variant, score it and write the table."""
    args = parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    results = {}
    for name in args.variants:
        labels_dir = osp.join(args.out, name)
        start = time.time()
        generate_occupancy(args.root_path, args.version, labels_dir,
                           LabelConfig(**VARIANTS[name][1]),
                           workers=args.workers, scenes=args.scenes)
        print(f'{name}: generated in {time.time() - start:.0f} s')
        results[name] = score(args.root_path, labels_dir, args.scenes)
        results[name]['seconds_per_key_frame'] = seconds_per_key_frame(
            labels_dir)
    text = table(results)
    header = (f'Generated labels against the labels of {args.root_path} '
              f'({results[args.variants[0]]["samples"]["occ3d"]} key '
              'frames); IoU in %.\n\n')
    if args.reach:
        reached = reach(args.root_path, args.version, args.scenes)
        results['reach'] = reached
        text += ('\n\nReference occupied voxels some ray of the scene '
                 f'reaches: {reached["share_reached"]:.1f} %; per class: '
                 + ', '.join(f'{name} {pct(100 * r / o)}' for name, o, r in
                             zip(OCC3D_CLASS_NAMES, reached['occupied'],
                                 reached['reached']) if o))
    with open(osp.join(args.out, 'quality.md'), 'w') as f:
        f.write(header + text + '\n')
    with open(osp.join(args.out, 'quality.json'), 'w') as f:
        json.dump(results, f, indent=1)
    print('\n' + header + text)
    return results


if __name__ == '__main__':
    main()
