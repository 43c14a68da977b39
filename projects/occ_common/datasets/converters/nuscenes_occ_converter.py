"""nuScenes (real or synthetic) -> mmdet3d v2 info files for occupancy.

Walks every sample of a nuScenes database with nuscenes-devkit and writes
``<prefix>_infos_{train,val,val_rainy,val_night}.pkl`` (``v1.0-test``:
``<prefix>_infos_test.pkl``), each ``dict(metainfo, data_list)``. The keys of
a sample are listed in :mod:`..info_format` and in the repository's
docs/dataset_prepare.md. All matrices are 4x4 (``cam2img`` 3x3) nested
lists, row-major, mapping column vectors: ``p_cam = lidar2cam @ p_lidar``.

Splits:
    * ``v1.0-trainval``: ``train`` / ``val`` of ``nuscenes.utils.splits``.
    * ``v1.0-mini``: ``mini_train`` / ``mini_val``.
    * ``v1.0-test``: ``test`` (of a synthetic world: all its scenes).
    * Synthetic worlds (recognised by the generator's
      ``synthetic_gt/meta.json`` under the root): the last
      ``max(1, n_scenes // 5)`` scenes in name order are ``val``, the others
      ``train``; a one-scene world uses its scene for both.
    * ``val_scenes`` overrides any of these (all other scenes are train).
    ``val_rainy`` / ``val_night`` are the ``val`` samples whose scene
    description mentions rain / night. A ``train``, ``val`` or ``test``
    split without any scene is an error naming the scenes there are.

Cameras and LiDAR layout come from the data: the cameras are the
``camera`` channels of the ``sensor`` table (the six nuScenes cameras in
mmdet3d's order, any other rig in its table's order), and the values per
LiDAR point are nuScenes' five unless given (a synthetic world records
its own).

Every file an info links (key frame, sweeps, images, lidarseg labels,
occupancy labels) is checked to exist; an occupancy label folder that does
not exist at all is recorded as ``None`` (with a warning) because users often
have only one of SurroundOcc / Occ3D. A missing key frame or image stops
the conversion; missing sweeps, a missing label file or a lidarseg /
panoptic table without its files are reported at the end and the rest is
converted (:mod:`.report` says why each is safe).
"""
import json
import multiprocessing
import os
import os.path as osp
import shutil
import sys
import tempfile
import warnings
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..info_format import (CAMERA_NAMES, INFO_VERSION, NUM_POINT_FEATS,
                           camera_order, weather_flags)
from ..nuscenes_classes import OCC_CLASS_NAMES
from .devkit_view import devkit_view
from .key_frame_links import link_previous_key_frames
from .label_files import (exists_or_report, label_roots, occ_label_paths,
                          rel_path)
from .report import ConversionReport

#: File that marks a root written by the synthetic world generator
#: (``tools/dataset_converters/create_synthetic_nuscenes.py``).
SYNTHETIC_MARKER = osp.join('synthetic_gt', 'meta.json')


def is_synthetic_root(root_path: str) -> bool:
    """Whether ``root_path`` holds a world of the synthetic generator."""
    return osp.isfile(osp.join(root_path, SYNTHETIC_MARKER))


def pose_matrix(record: dict) -> np.ndarray:
    """4x4 rigid transform of a ``calibrated_sensor`` / ``ego_pose`` record.

    Args:
        record (dict): Has ``rotation`` (w, x, y, z quaternion) and
            ``translation`` (3,).

    Returns:
        np.ndarray: Shape (4, 4), float64, sensor (or ego) to parent frame.
    """
    from pyquaternion import Quaternion
    mat = np.eye(4)
    mat[:3, :3] = Quaternion(record['rotation']).rotation_matrix
    mat[:3, 3] = record['translation']
    return mat


def _must_exist(path: str, what: str, sample_token: str) -> None:
    if not osp.isfile(path):
        raise FileNotFoundError(
            f'{what} of sample {sample_token} not found: {path}')


def rig_cameras(sensors: Sequence[dict]) -> Tuple[str, ...]:
    """The camera channels of a database's ``sensor`` table, in the order
    the info files list them.

    Args:
        sensors (Sequence[dict]): ``sensor`` records (``channel``,
            ``modality``).

    Returns:
        tuple[str, ...]: nuScenes' six cameras in mmdet3d's order
        (:data:`~..info_format.CAMERA_NAMES`) when the rig is theirs, any
        other rig's cameras in the table's order.

    Raises:
        ValueError: If the table lists no camera.
    """
    found = [s['channel'] for s in sensors if s['modality'] == 'camera']
    if not found:
        channels = [s['channel'] for s in sensors]
        raise ValueError('the sensor table lists no camera (modality '
                         f"'camera'); it has {channels}")
    return camera_order(found)


def synthetic_point_dims(root_path: str) -> Optional[int]:
    """Values per LiDAR point of a synthetic world (5 with the ring index,
    4 without), or None for a root the generator did not write."""
    if not is_synthetic_root(root_path):
        return None
    with open(osp.join(root_path, SYNTHETIC_MARKER)) as f:
        parameters = json.load(f).get('parameters', {})
    # Worlds written before the option existed all have the ring index.
    return NUM_POINT_FEATS if parameters.get('lidar_ring', True) else 4


class _Context:
    """What every sample needs: the devkit handle and the label roots."""

    def __init__(self, nusc, root: str, surroundocc_root: Optional[str],
                 occ3d_root: Optional[str], max_sweeps: int,
                 num_pts_feats: int = NUM_POINT_FEATS):
        self.nusc = nusc
        self.root = root
        self.surroundocc_root = surroundocc_root
        self.occ3d_root = occ3d_root
        self.max_sweeps = max_sweeps
        self.num_pts_feats = num_pts_feats
        self.cam_names = rig_cameras(nusc.sensor)
        self.has_lidarseg = hasattr(nusc, 'lidarseg')
        self.report = ConversionReport()

    def sensor2global(self, sd: dict) -> np.ndarray:
        cs = self.nusc.get('calibrated_sensor', sd['calibrated_sensor_token'])
        ep = self.nusc.get('ego_pose', sd['ego_pose_token'])
        return pose_matrix(ep) @ pose_matrix(cs)


def _sweeps(ctx: _Context, lidar_sd: dict, global2lidar: np.ndarray,
            sample_token: str) -> List[dict]:
    """Up to ``max_sweeps`` earlier LiDAR sweeps, newest first.

    The layout is mmdet3d 1.4's (``lidar_points.lidar_path``,
    ``lidar_points.lidar2sensor``, ``timestamp`` in seconds);
    ``lidar2sensor`` is the exact inverse of ``sensor2lidar`` (key-frame
    LiDAR -> sweep LiDAR), as mmdet3d's own converter writes it.
    """
    nusc, sweeps, sd = ctx.nusc, [], lidar_sd
    while len(sweeps) < ctx.max_sweeps and sd['prev']:
        sd = nusc.get('sample_data', sd['prev'])
        path = osp.join(ctx.root, sd['filename'])
        if not osp.isfile(path):
            # A keyframe-only download: keep the sweeps before the gap.
            ctx.report.add(
                'missing LiDAR sweeps (the sample keeps those before)',
                f'sample {sample_token}: {len(sweeps)} of {ctx.max_sweeps}'
                f', {path} missing')
            break
        cs = nusc.get('calibrated_sensor', sd['calibrated_sensor_token'])
        ep = nusc.get('ego_pose', sd['ego_pose_token'])
        sensor2lidar = global2lidar @ pose_matrix(ep) @ pose_matrix(cs)
        sweeps.append(
            dict(
                lidar_points=dict(
                    lidar_path=rel_path(path, ctx.root),
                    lidar2ego=pose_matrix(cs).tolist(),
                    lidar2sensor=np.linalg.inv(sensor2lidar).tolist(),
                    sensor2lidar=sensor2lidar.tolist()),
                ego2global=pose_matrix(ep).tolist(),
                timestamp=sd['timestamp'] / 1e6,
                sample_data_token=sd['token'],
                is_key_frame=sd['is_key_frame']))
    return sweeps


def _images(ctx: _Context, sample: dict, global2lidar: np.ndarray,
            cam_names: Sequence[str]) -> Dict[str, dict]:
    """Per-camera paths and calibration, in the key-frame LiDAR frame."""
    nusc, images = ctx.nusc, {}
    for cam in cam_names:
        if cam not in sample['data']:
            raise ValueError(f'sample {sample["token"]} has no {cam} image; '
                             f'expected the cameras {list(cam_names)}')
        sd = nusc.get('sample_data', sample['data'][cam])
        path = osp.join(ctx.root, sd['filename'])
        _must_exist(path, f'{cam} image', sample['token'])
        cs = nusc.get('calibrated_sensor', sd['calibrated_sensor_token'])
        cam2img = np.asarray(cs['camera_intrinsic'], dtype=np.float64)
        # The camera and the LiDAR fire at different times: go through the
        # global frame with each sensor's own ego pose.
        lidar2cam = np.linalg.inv(global2lidar @ ctx.sensor2global(sd))
        viewpad = np.eye(4)
        viewpad[:3, :3] = cam2img
        images[cam] = dict(
            img_path=rel_path(path, ctx.root),
            # The image size the intrinsics belong to: the loader refuses
            # an image of another size (or rescales cam2img if asked).
            height=int(sd['height']),
            width=int(sd['width']),
            cam2img=cam2img.tolist(),
            lidar2cam=lidar2cam.tolist(),
            cam2ego=pose_matrix(cs).tolist(),
            lidar2img=(viewpad @ lidar2cam).tolist(),
            sample_data_token=sd['token'],
            timestamp=sd['timestamp'] / 1e6)
    return images


def _label_paths(ctx: _Context, sample: dict, scene: dict,
                 lidar_sd: dict) -> dict:
    """Paths of the lidarseg and both occupancy labels (``None``: absent)."""
    token, paths = sample['token'], {}
    paths['pts_semantic_mask_path'] = None
    if ctx.has_lidarseg:
        try:
            rec = ctx.nusc.get('lidarseg', lidar_sd['token'])
        except KeyError:
            rec = None  # e.g. the test split has no labels.
        if rec is not None:
            path = osp.join(ctx.root, rec['filename'])
            if exists_or_report(path, 'lidarseg label', token, ctx.report):
                paths['pts_semantic_mask_path'] = rel_path(path, ctx.root)
    paths.update(
        occ_label_paths(ctx.root, ctx.surroundocc_root, ctx.occ3d_root,
                        lidar_sd['filename'], scene['name'], token,
                        ctx.report))
    return paths


def sample_info(ctx: _Context, sample: dict, scene: dict,
                cam_names: Optional[Sequence[str]] = None) -> dict:
    """The info dict of one key frame (``sample_idx`` is set by the caller).

    Args:
        ctx (_Context): Devkit handle and label roots.
        sample (dict): A ``sample`` record.
        scene (dict): Its ``scene`` record.
        cam_names (Sequence[str], optional): Cameras to link. Defaults to
            the rig's (:func:`rig_cameras`).

    Returns:
        dict: One ``data_list`` entry (see the module docstring).
    """
    nusc = ctx.nusc
    lidar_sd = nusc.get('sample_data', sample['data']['LIDAR_TOP'])
    lidar_path = osp.join(ctx.root, lidar_sd['filename'])
    _must_exist(lidar_path, 'LiDAR key frame', sample['token'])
    point_bytes = 4 * ctx.num_pts_feats
    if osp.getsize(lidar_path) % point_bytes:
        raise ValueError(
            f'LiDAR key frame of sample {sample["token"]}: {lidar_path} has '
            f'{osp.getsize(lidar_path)} bytes, not a whole number of points '
            f'of {ctx.num_pts_feats} float32 values; pass the values per '
            'point of your LiDAR files (--num-pts-feats).')
    cs = nusc.get('calibrated_sensor', lidar_sd['calibrated_sensor_token'])
    ep = nusc.get('ego_pose', lidar_sd['ego_pose_token'])
    lidar2ego, ego2global = pose_matrix(cs), pose_matrix(ep)
    global2lidar = np.linalg.inv(ego2global @ lidar2ego)
    info = dict(
        sample_idx=-1,
        token=sample['token'],
        timestamp=lidar_sd['timestamp'] / 1e6,
        scene_token=scene['token'],
        scene_name=scene['name'],
        scene_description=scene['description'],
        **weather_flags(scene['description']),
        prev=sample['prev'],
        next=sample['next'],
        ego2global=ego2global.tolist(),
        lidar_points=dict(
            num_pts_feats=ctx.num_pts_feats,
            lidar_path=rel_path(lidar_path, ctx.root),
            lidar2ego=lidar2ego.tolist()),
        lidar_sweeps=_sweeps(ctx, lidar_sd, global2lidar, sample['token']),
        images=_images(ctx, sample, global2lidar,
                       ctx.cam_names if cam_names is None else cam_names))
    info.update(_label_paths(ctx, sample, scene, lidar_sd))
    return info


def split_scenes(scene_names: Sequence[str],
                 version: str,
                 val_scenes: Optional[Sequence[str]] = None,
                 synthetic: bool = False) -> Dict[str, List[str]]:
    """Scene names per split (see the module docstring for the rules).

    Args:
        scene_names (Sequence[str]): Scenes present in the database.
        version (str): nuScenes version, e.g. ``'v1.0-trainval'``.
        val_scenes (Sequence[str], optional): Explicit val scenes.
        synthetic (bool): The database is a synthetic world.
            Defaults to False.

    Returns:
        dict[str, list[str]]: ``train`` and ``val`` (or only ``test``).
    """
    names = sorted(scene_names)
    if version == 'v1.0-test' and (synthetic or val_scenes is not None):
        if val_scenes is not None:
            raise ValueError('--val-scenes does not apply to v1.0-test, '
                             'whose scenes are all test scenes')
        return dict(test=names)
    if val_scenes is not None:
        unknown = sorted(set(val_scenes) - set(names))
        if unknown:
            raise ValueError(f'val scenes {unknown} are not in the database '
                             f'(it has {names})')
        val = [n for n in names if n in set(val_scenes)]
        return dict(train=[n for n in names if n not in set(val)], val=val)
    if synthetic:
        if len(names) == 1:
            warnings.warn(f'synthetic world with one scene ({names[0]}): it '
                          'is used for both train and val')
            return dict(train=names, val=names)
        num_val = max(1, len(names) // 5)
        return dict(train=names[:-num_val], val=names[-num_val:])
    from nuscenes.utils.splits import create_splits_scenes
    splits = create_splits_scenes()
    present = set(names)
    if version == 'v1.0-test':
        return dict(test=[n for n in splits['test'] if n in present])
    keys = dict(train='mini_train', val='mini_val') \
        if version == 'v1.0-mini' else dict(train='train', val='val')
    return {
        split: [n for n in splits[key] if n in present]
        for split, key in keys.items()
    }


def write_info_file(path: str, entries: List[dict], version: str,
                    split: str, synthetic: bool,
                    cameras: Sequence[str] = CAMERA_NAMES,
                    **extra) -> None:
    """Write one ``dict(metainfo, data_list)`` info file.

    Args:
        path (str): The pickle to write.
        entries (list[dict]): Samples (``sample_idx`` is set here).
        version (str): nuScenes version.
        split (str): Split name.
        synthetic (bool): Written from a synthetic world.
        cameras (Sequence[str]): The cameras every sample links, in order.
            Defaults to nuScenes' six.
        **extra: Further metainfo.
    """
    import mmengine
    metainfo = dict(
        dataset='nuscenes-occ',
        version=version,
        info_version=INFO_VERSION,
        classes=OCC_CLASS_NAMES,
        split=split,
        scenes=sorted({str(e['scene_name'])
                       for e in entries}),
        synthetic=synthetic,
        cameras=tuple(cameras),
        **extra)
    data_list = [dict(e, sample_idx=i) for i, e in enumerate(entries)]
    mmengine.dump(dict(metainfo=metainfo, data_list=data_list), path)


#: The conversion state of worker processes (inherited when they fork).
_WORKER_CTX: Optional[_Context] = None


def _convert_sample(task: Tuple[str, str]) -> Tuple[dict, ConversionReport]:
    """One sample's info and what it reported (run in a worker)."""
    ctx = _WORKER_CTX
    ctx.report = ConversionReport()
    token, scene_token = task
    info = sample_info(ctx, ctx.nusc.get('sample', token),
                       ctx.nusc.get('scene', scene_token))
    return info, ctx.report


def convert_samples(ctx: _Context, tasks: List[Tuple[str, str]],
                    workers: int) -> List[dict]:
    """``sample_info`` of every ``(sample token, scene token)``, in order,
    with a progress bar; ``workers`` > 1 forks that many processes (the
    devkit tables are shared, not pickled)."""
    from mmengine.utils import ProgressBar
    global _WORKER_CTX
    _WORKER_CTX = ctx
    report, infos = ctx.report, []
    bar = ProgressBar(len(tasks), file=sys.stdout)
    pool = multiprocessing.get_context('fork').Pool(workers) \
        if workers > 1 and len(tasks) > 1 else None
    try:
        results = map(_convert_sample, tasks) if pool is None else \
            pool.imap(_convert_sample, tasks, chunksize=4)
        for info, sample_report in results:
            infos.append(info)
            report.extend(sample_report)
            bar.update()
    finally:
        ctx.report, _WORKER_CTX = report, None
        if pool is not None:
            pool.close()
            pool.join()
    print()
    return infos


def create_nuscenes_occ_infos(root_path: str,
                              out_dir: Optional[str] = None,
                              info_prefix: str = 'nuscenes_occ',
                              version: str = 'v1.0-trainval',
                              surroundocc_root: Optional[str] = None,
                              occ3d_root: Optional[str] = None,
                              max_sweeps: int = 10,
                              val_scenes: Optional[Sequence[str]] = None,
                              overwrite: bool = False,
                              workers: int = 0,
                              num_pts_feats: Optional[int] = None
                              ) -> Dict[str, str]:
    """Write the info files of a nuScenes root (real or synthetic).

    Args:
        root_path (str): nuScenes data root (holds ``samples/``, ``sweeps/``,
            ``<version>/``).
        out_dir (str, optional): Where the pickles go. Defaults to
            ``root_path``.
        info_prefix (str): File name prefix. Defaults to 'nuscenes_occ'.
        version (str): nuScenes version. Defaults to 'v1.0-trainval'.
        surroundocc_root (str, optional): SurroundOcc label folder (holds
            ``samples/*.pcd.bin.npy``). Defaults to
            ``<root_path>/nuscenes_occ``.
        occ3d_root (str, optional): Occ3D label folder (holds
            ``<scene>/<sample token>/labels.npz``). Defaults to
            ``<root_path>/gts``.
        max_sweeps (int): Earlier sweeps to link per sample. Defaults to 10.
        val_scenes (Sequence[str], optional): Explicit val scene names.
        overwrite (bool): Replace existing info files. Defaults to False.
        workers (int): Processes converting samples (0 or 1: this one).
            Defaults to 0.
        num_pts_feats (int, optional): float32 values per point of the
            LiDAR files. Defaults to a synthetic world's own (4 or 5), else
            nuScenes' 5 (x, y, z, intensity, ring).

    Returns:
        dict[str, str]: Split name -> written file.

    Raises:
        FileExistsError: An info file exists and ``overwrite`` is False.
        FileNotFoundError: A key frame or image is missing (the message
            names it); what can be skipped safely is reported instead.
    """
    from nuscenes import NuScenes
    out_dir = out_dir or root_path
    targets = dict()
    for split in (('test', ) if version == 'v1.0-test' else
                  ('train', 'val', 'val_rainy', 'val_night')):
        targets[split] = osp.join(out_dir, f'{info_prefix}_infos_{split}.pkl')
    existing = [p for p in targets.values() if osp.exists(p)]
    if existing and not overwrite:
        raise FileExistsError(f'info files already exist: {existing}; pass '
                              '--overwrite to replace them')
    roots = label_roots(root_path, surroundocc_root, occ3d_root)
    if not osp.isdir(osp.join(root_path, version)):
        found = sorted(d for d in os.listdir(root_path)
                       if d.startswith('v1.0')) if osp.isdir(root_path) \
            else []
        raise FileNotFoundError(
            f'{osp.join(root_path, version)} not found: {root_path} holds '
            f'the nuScenes versions {found}; pass one with --version.')
    report = ConversionReport()
    view_dir = tempfile.mkdtemp(prefix='nuscenes_view_')
    try:
        nusc = NuScenes(
            version=version,
            dataroot=devkit_view(root_path, version, view_dir, report),
            verbose=False)
    finally:
        shutil.rmtree(view_dir)
    if num_pts_feats is None:
        num_pts_feats = synthetic_point_dims(root_path) or NUM_POINT_FEATS
    if not isinstance(num_pts_feats, int) or num_pts_feats < 3:
        raise ValueError('num_pts_feats must be an int >= 3 (x, y, z '
                         f'first), got {num_pts_feats!r}')
    ctx = _Context(nusc, root_path, *roots, max_sweeps, num_pts_feats)
    ctx.report = report
    scenes = {s['name']: s for s in nusc.scene}
    synthetic = is_synthetic_root(root_path)
    splits = split_scenes(list(scenes), version, val_scenes, synthetic)
    empty = [split for split, names in splits.items() if not names]
    if empty:
        raise ValueError(
            f'{root_path} ({version}): the {" and ".join(empty)} split '
            f'would hold no sample. The database has the scenes '
            f'{sorted(scenes)}; the splits are {splits}. Check --version '
            '(its official splits list other scenes), or choose the val '
            'scenes with --val-scenes.')
    data = {}
    for split, names in splits.items():
        tasks = []
        for name in names:
            token = scenes[name]['first_sample_token']
            while token:
                tasks.append((token, scenes[name]['token']))
                token = nusc.get('sample', token)['next']
        print(f'{version} {split}: {len(tasks)} samples of {len(names)} '
              'scenes')
        data[split] = link_previous_key_frames(
            convert_samples(ctx, tasks, workers))
    if 'val' in data:
        data['val_rainy'] = [e for e in data['val'] if e['is_rainy']]
        data['val_night'] = [e for e in data['val'] if e['is_night']]
        # The subsets are chosen by the scene description's words, not by
        # a published list (OCCFusion's are not public as text): their
        # sizes are printed so that a table can state them.
        for split in ('val_rainy', 'val_night'):
            scene_count = len({e['scene_token'] for e in data[split]})
            print(f'{version} {split}: {len(data[split])} samples of '
                  f'{scene_count} scenes (description mentions '
                  f'{split[4:].replace("rainy", "rain")})')
    os.makedirs(out_dir, exist_ok=True)
    for split, entries in data.items():
        write_info_file(targets[split], entries, version, split, synthetic,
                        cameras=ctx.cam_names)
    ctx.report.emit(f'{root_path} ({version})')
    return targets
