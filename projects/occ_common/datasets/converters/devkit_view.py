"""A nuScenes root that nuscenes-devkit opens despite missing label files.

nuscenes-devkit asserts one file per record of ``lidarseg.json`` and
``panoptic.json``; a keyframe-only or partial download stops it before
anything is converted. :func:`devkit_view` hides what is missing.
"""
import json
import os
import os.path as osp

from .report import ConversionReport


def devkit_view(root_path: str, version: str, view_dir: str,
                report: ConversionReport) -> str:
    """A root for nuscenes-devkit without label tables whose files are gone.

    nuscenes-devkit asserts that ``lidarseg.json`` / ``panoptic.json`` have
    exactly one file per record, so one missing file (or ``panoptic.json``
    unpacked without ``panoptic/``) stops it. The view links everything of
    ``root_path`` but writes its own ``<version>/`` with: panoptic dropped
    when a file is missing (never read here), lidarseg reduced to the
    records whose file exists (the others are reported). A root without
    such problems is returned as it is.

    Args:
        root_path (str): nuScenes root.
        version (str): Its version folder.
        view_dir (str): An empty folder for the view.
        report (ConversionReport): Where the hidden records are recorded.

    Returns:
        str: The root to give nuscenes-devkit.
    """
    tables = osp.join(root_path, version)
    kept = {}
    for task in ('lidarseg', 'panoptic'):
        path = osp.join(tables, f'{task}.json')
        if not osp.isfile(path):
            continue
        with open(path) as f:
            records = json.load(f)
        present = [r for r in records
                   if osp.isfile(osp.join(root_path, r['filename']))]
        if len(present) == len(records):
            continue
        missing = [r['filename'] for r in records if r not in present]
        if task == 'panoptic':
            report.add('panoptic table without its files (ignored: '
                       'never read)', f'{len(missing)} of {len(records)} '
                       f'files missing, e.g. {missing[0]}')
            kept[task] = None
        else:
            for name in missing:
                report.add('missing lidarseg label (recorded as None)',
                           osp.join(root_path, name))
            kept[task] = present
    if not kept:
        return root_path
    for name in os.listdir(root_path):
        if name != version and name not in kept:
            os.symlink(osp.join(root_path, name), osp.join(view_dir, name))
    os.makedirs(osp.join(view_dir, version))
    for name in os.listdir(tables):
        task = name[:-len('.json')]
        if task not in kept:
            os.symlink(osp.join(tables, name),
                       osp.join(view_dir, version, name))
        elif kept[task] is not None:
            with open(osp.join(view_dir, version, name), 'w') as f:
                json.dump(kept[task], f)
    for task, records in kept.items():
        if records is None:
            continue
        # Only the present files: the devkit counts them.
        folder = osp.join(view_dir, task, version)
        os.makedirs(folder)
        for rec in records:
            os.symlink(osp.join(root_path, rec['filename']),
                       osp.join(folder, osp.basename(rec['filename'])))
    return view_dir
