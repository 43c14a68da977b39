"""Occupancy labels for every scene of a nuScenes-format dataset.

:func:`generate_occupancy` opens the tables with nuscenes-devkit and
writes each scene's labels (:func:`.scene_labels.write_scene`), in
parallel over scenes. It resumes: a scene is marked done
(``<out>/progress/<scene>.json``) only after all its files are written, so
a finished scene is skipped and one that was interrupted is done again.
``<out>/generation.json`` records the settings; a run with other settings
into the same folder is refused instead of mixing two kinds of labels.
"""
import json
import multiprocessing
import os
import os.path as osp
import shutil
import sys
import tempfile
from typing import Optional, Sequence

from ..converters.devkit_view import devkit_view
from ..converters.report import ConversionReport
from .config import LabelConfig
from .scene_labels import write_scene
from .sequence import plain_name, read_scene

#: The settings file and the folder of per-scene done markers.
SETTINGS_FILE, PROGRESS_DIR = 'generation.json', 'progress'

#: The state of worker processes (inherited when they fork).
_WORKER: dict = {}


def _done_path(out_dir: str, scene: str) -> str:
    return osp.join(out_dir, PROGRESS_DIR,
                    f'{plain_name(scene, "scene name")}.json')


def _check_settings(out_dir: str, settings: dict, overwrite: bool) -> None:
    path = osp.join(out_dir, SETTINGS_FILE)
    if osp.isfile(path):
        with open(path) as f:
            old = json.load(f)
        if old != settings:
            if not overwrite:
                raise FileExistsError(
                    f'{out_dir} holds labels made with other settings '
                    f'({path}: {old}, now {settings}); choose another '
                    'output folder or pass --overwrite to redo every scene.')
            shutil.rmtree(osp.join(out_dir, PROGRESS_DIR), ignore_errors=True)
    os.makedirs(osp.join(out_dir, PROGRESS_DIR), exist_ok=True)
    with open(path, 'w') as f:
        json.dump(settings, f, indent=1)


def _scene_job(name: str) -> dict:
    """Label one scene and mark it done (runs in a worker)."""
    nusc, root = _WORKER['nusc'], _WORKER['root']
    out_dir, cfg = _WORKER['out'], _WORKER['cfg']
    sequence = read_scene(
        nusc, next(s for s in nusc.scene if s['name'] == name), root)
    result = write_scene(sequence, out_dir, cfg)
    result['files'] = [osp.relpath(p, out_dir) for p in result['files']]
    result['missing'] = sequence.missing
    with open(_done_path(out_dir, name), 'w') as f:
        json.dump(result, f)
    return result


def generate_occupancy(root_path: str,
                       version: str,
                       out_dir: str,
                       cfg: Optional[LabelConfig] = None,
                       workers: int = 0,
                       scenes: Optional[Sequence[str]] = None,
                       overwrite: bool = False,
                       progress: bool = True) -> dict:
    """Write Occ3D and SurroundOcc labels of a dataset's scenes.

    Args:
        root_path (str): nuScenes root (``samples/``, ``sweeps/``,
            ``<version>/``, optionally ``lidarseg/``).
        version (str): Table folder, e.g. ``'v1.0-trainval'``.
        out_dir (str): Output root: ``gts/`` (Occ3D),
            ``nuscenes_occ/`` (SurroundOcc), ``generation.json``,
            ``progress/``.
        cfg (LabelConfig, optional): Settings. Defaults to
            ``LabelConfig()``.
        workers (int): Processes, one scene each at a time (0 or 1: this
            one). Defaults to 0.
        scenes (Sequence[str], optional): Scene names to label. Defaults
            to all.
        overwrite (bool): Relabel every scene, also with other settings
            than the folder's. Defaults to False.
        progress (bool): Show a progress bar of the scenes.
            Defaults to True.

    Returns:
        dict: ``scenes`` (labelled now), ``skipped`` (done before),
        ``key_frames`` and ``files`` written now.

    Raises:
        FileNotFoundError: No ``<root_path>/<version>``.
        FileExistsError: ``out_dir`` holds labels of other settings and
            ``overwrite`` is False.
        ValueError: An unknown scene name.
    """
    from nuscenes import NuScenes
    cfg = cfg or LabelConfig()
    if not osp.isdir(osp.join(root_path, version)):
        raise FileNotFoundError(f'{osp.join(root_path, version)} not found: '
                                'pass the dataset root and its version.')
    settings = dict(version=version, config=cfg.to_dict())
    _check_settings(out_dir, settings, overwrite)
    report = ConversionReport()
    view_dir = tempfile.mkdtemp(prefix='nuscenes_view_')
    try:
        nusc = NuScenes(version=version, verbose=False,
                        dataroot=devkit_view(root_path, version, view_dir,
                                             report))
    finally:
        shutil.rmtree(view_dir)
    names = sorted(s['name'] for s in nusc.scene)
    if scenes is not None:
        unknown = sorted(set(scenes) - set(names))
        if unknown:
            raise ValueError(f'scenes {unknown} are not in {root_path} '
                             f'({version}), which has {names}.')
        names = [n for n in names if n in set(scenes)]
    todo = [n for n in names
            if overwrite or not osp.isfile(_done_path(out_dir, n))]
    summary = dict(scenes=[], skipped=sorted(set(names) - set(todo)),
                   key_frames=0, files=0)
    _WORKER.update(nusc=nusc, root=root_path, out=out_dir, cfg=cfg)
    bar = None
    if progress and todo:
        from mmengine.utils import ProgressBar
        bar = ProgressBar(len(todo), file=sys.stderr)
    pool = multiprocessing.get_context('fork').Pool(workers) \
        if workers > 1 and len(todo) > 1 else None
    try:
        results = map(_scene_job, todo) if pool is None else \
            pool.imap_unordered(_scene_job, todo)
        for result in results:
            summary['scenes'].append(result['scene'])
            summary['key_frames'] += result['key_frames']
            summary['files'] += len(result['files'])
            for path in result['missing']:
                report.add('missing LiDAR sweeps (labels made from the '
                           'others)', f'{result["scene"]}: {path}')
            if bar is not None:
                bar.update()
    finally:
        _WORKER.clear()
        if pool is not None:
            pool.close()
            pool.join()
    if bar is not None:
        sys.stderr.write('\n')
    report.emit(f'{root_path} ({version})')
    return summary
