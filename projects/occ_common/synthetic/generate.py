"""Entry point: write a synthetic nuScenes-format world to disk.

Layout written under ``out_dir`` (the real nuScenes / SurroundOcc / Occ3D
layouts, plus one ``synthetic_gt/`` folder of generator-only extras)::

    v1.0-mini/*.json                    nuScenes tables + lidarseg.json
    maps/<token>.png                    semantic prior (0.1 m / pixel)
    samples/CAM_*/<log>__CAM_*__<ts>.jpg         key-frame images
    samples/LIDAR_TOP/<log>__LIDAR_TOP__<ts>.pcd.bin   key-frame sweeps
    sweeps/LIDAR_TOP/<log>__LIDAR_TOP__<ts>.pcd.bin    other sweeps
    lidarseg/v1.0-mini/<lidar sd token>_lidarseg.bin   uint8 raw labels
    nuscenes_occ/samples/<key-frame lidar file>.npy    SurroundOcc GT
    gts/<scene name>/<sample token>/labels.npz         Occ3D GT
    synthetic_gt/meta.json              parameters and summary
    synthetic_gt/worlds/<scene>.json    each scene's world (boxes, layout)
    synthetic_gt/cam_labels/CAM_*/<image stem>.png     raw lidarseg class
                                        seen at every pixel (0 = sky)

Timing follows nuScenes: the LiDAR spins at 20 Hz; every
``sweeps_per_sample``-th sweep is a key frame (10 gives nuScenes' 2 Hz with
9 sweeps in between), and 10 sweeps precede a scene's first key frame, so
every key frame reaches >= 10 earlier sweeps through ``prev``. A non-key
sweep's ``sample_token`` is its nearest key frame's, as in nuScenes. Occ3D's
``mask_lidar`` aggregates the key frame's sweep and the
``sweeps_per_sample - 1`` sweeps before it.
"""
import json
import os
import os.path as osp
import shutil
import sys
import time
from collections import deque
from datetime import datetime, timedelta, timezone
from typing import Optional, Sequence, Tuple

import cv2
import numpy as np

from ..fileio.safe_names import safe_file_name
from .camera import CAMERA_RIGS, make_camera_rig
from .layout import build_world
from .lidar import make_lidar2ego
from .scene_writer import SceneWriter
from .tables import NuScenesTables, make_token
from .world import World, world_from_dict, world_to_dict

#: Version of the on-disk format written here (stored in meta.json).
FORMAT_VERSION = 1
#: LiDAR sweeps before a scene's first key frame.
PRE_SWEEPS = 10
SWEEP_PERIOD_S = 0.05
CONDITIONS = {'clear': (False, False), 'rain': (True, False),
              'night': (False, True), 'night_rain': (True, True)}
#: Conditions of scenes 0, 1, 2, ... when none are given: two scenes
#: already cover a clear day and a rainy night.
DEFAULT_CONDITIONS = ('clear', 'night_rain', 'rain', 'night')
_LOCATIONS = ('singapore-onenorth', 'boston-seaport',
              'singapore-queenstown', 'singapore-hollandvillage')
#: Folders this generator owns under ``out_dir``.
_OWNED = ('samples', 'sweeps', 'maps', 'nuscenes_occ', 'gts',
          'synthetic_gt')
META_PATH = osp.join('synthetic_gt', 'meta.json')


def load_world(out_dir: str, scene_name: str) -> World:
    """The world of one scene of a generated dataset, e.g. to find a static
    building or the exact box of an object in a test.

    Args:
        out_dir (str): Dataset root written by
            :func:`generate_synthetic_nuscenes`.
        scene_name (str): ``scene-XXXX``.

    Returns:
        World: The scene's world (boxes at t = 0 s, the scene's first
        sweep; ``World.boxes.centers_at(t)`` moves them).

    Raises:
        FileNotFoundError: If the scene's world file is missing.
    """
    scene_name = safe_file_name(scene_name, 'scene name')
    path = osp.join(out_dir, 'synthetic_gt', 'worlds', f'{scene_name}.json')
    if not osp.isfile(path):
        raise FileNotFoundError(
            f'No synthetic world for {scene_name!r}: expected {path}.')
    with open(path) as f:
        return world_from_dict(json.load(f))


def _check_args(num_scenes, samples_per_scene, sweeps_per_sample,
                image_size, version, seed, azimuth_bins, conditions,
                camera_rig, lidar_ring):
    for name, value, low in (('num_scenes', num_scenes, 1),
                             ('samples_per_scene', samples_per_scene, 1),
                             ('sweeps_per_sample', sweeps_per_sample, 1),
                             ('seed', seed, 0),
                             ('azimuth_bins', azimuth_bins, 8)):
        if not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f'Expected {name} to be an int >= {low}, got '
                             f'{value!r}.')
    size = tuple(image_size) if isinstance(image_size, (tuple, list)) else ()
    if len(size) != 2 or not all(
            isinstance(v, (int, np.integer)) and v >= 8 for v in size):
        raise ValueError('Expected image_size = (width, height), two ints '
                         f'>= 8, got {image_size!r}.')
    if (not isinstance(version, str) or not version
            or osp.basename(version) != version):
        raise ValueError('Expected version to be a folder name like '
                         f"'v1.0-mini', got {version!r}.")
    if camera_rig not in CAMERA_RIGS:
        raise ValueError(f'Expected camera_rig to be one of '
                         f'{sorted(CAMERA_RIGS)}, got {camera_rig!r}.')
    if not isinstance(lidar_ring, (bool, np.bool_)):
        raise ValueError(f'Expected lidar_ring to be a bool, got '
                         f'{lidar_ring!r}.')
    if conditions is not None:
        if (isinstance(conditions, str) or len(conditions) != num_scenes
                or any(c not in CONDITIONS for c in conditions)):
            raise ValueError(
                f'Expected conditions to list one of {sorted(CONDITIONS)} '
                f'per scene ({num_scenes}), got {conditions!r}.')


def _prepare_out_dir(out_dir: str, version: str, overwrite: bool) -> None:
    """Refuses to clobber data; with ``overwrite``, removes an earlier
    synthetic world (and only one this generator wrote)."""
    existing = [p for p in (version, ) + _OWNED + (osp.join(
        'lidarseg', version), ) if osp.exists(osp.join(out_dir, p))]
    if not existing:
        return
    if not overwrite:
        raise FileExistsError(
            f'{out_dir} already holds {", ".join(existing)}; pass '
            'overwrite=True (--overwrite) to replace the synthetic world.')
    if not osp.isfile(osp.join(out_dir, META_PATH)):
        raise FileExistsError(
            f'{out_dir} holds {", ".join(existing)} but no {META_PATH}: it '
            'is not a synthetic world, so it is never overwritten.')
    for path in existing:
        shutil.rmtree(osp.join(out_dir, path))


def _write_meta(out_dir: str, meta: dict) -> None:
    path = osp.join(out_dir, META_PATH)
    os.makedirs(osp.dirname(path), exist_ok=True)
    with open(path, 'w') as f:
        json.dump(meta, f, indent=1)


def _write_map(out_dir: str, token: str, world, reach: float) -> str:
    """Writes the semantic prior (driveable surface and sidewalks = 255)
    as nuScenes' map rasters: 0.1 m per pixel, row 0 at the top (max
    global y)."""
    coarse, fine = 0.5, 0.1
    size = int(np.ceil(2 * reach / coarse))
    y, x = np.mgrid[0:size, 0:size]
    xy = np.stack([(x + 0.5) * coarse, (size - y - 0.5) * coarse], axis=-1)
    ground = world.ground_class(xy)
    prior = np.where((ground == 24) | (ground == 26), 255, 0).astype(
        np.uint8)
    scale = int(round(coarse / fine))
    prior = cv2.resize(prior, (size * scale, size * scale),
                       interpolation=cv2.INTER_NEAREST)
    token = safe_file_name(token, 'map token')
    filename = osp.join('maps', f'{token}.png')
    cv2.imwrite(osp.join(out_dir, filename), prior)
    return filename


def generate_synthetic_nuscenes(out_dir: str,
                                num_scenes: int = 2,
                                samples_per_scene: int = 4,
                                sweeps_per_sample: int = 10,
                                image_size: Tuple[int, int] = (480, 270),
                                version: str = 'v1.0-mini',
                                seed: int = 0,
                                overwrite: bool = False,
                                *,
                                azimuth_bins: int = 512,
                                conditions: Optional[Sequence[str]] = None,
                                camera_mask_rays: Optional[Tuple[int,
                                                                 int]] = None,
                                write_camera_labels: bool = True,
                                camera_rig: str = 'nuscenes',
                                lidar_ring: bool = True,
                                progress: bool = False) -> dict:
    """Writes a small, geometrically consistent nuScenes-format world.

    Args:
        out_dir (str): Dataset root to write (created if missing).
        num_scenes (int): Scenes, one world each. Defaults to 2.
        samples_per_scene (int): Key frames per scene. Defaults to 4.
        sweeps_per_sample (int): LiDAR sweeps per key-frame interval (10 =
            nuScenes' 20 Hz LiDAR and 2 Hz key frames). Defaults to 10.
        image_size (Tuple[int, int]): Camera ``(width, height)``.
            Defaults to (480, 270).
        version (str): Table folder and lidarseg sub-folder name.
            Defaults to 'v1.0-mini'.
        seed (int): Random seed; the same seed writes the same bytes
            (meta.json's timing aside). Defaults to 0.
        overwrite (bool): Replace an earlier synthetic world in
            ``out_dir``. Defaults to False.
        azimuth_bins (int): LiDAR azimuth steps per revolution (32 beams
            each). Defaults to 512.
        conditions (Sequence[str], optional): Per scene one of 'clear',
            'rain', 'night', 'night_rain'. Defaults to None (cycling through
            :data:`DEFAULT_CONDITIONS`).
        camera_mask_rays (Tuple[int, int], optional): Ray grid per camera
            for Occ3D's ``mask_camera``. Defaults to None (half the image
            size, clipped to 64x36 .. 400x225).
        write_camera_labels (bool): Write the per-pixel class maps to
            ``synthetic_gt/cam_labels``. Defaults to True.
        camera_rig (str): ``'nuscenes'`` (the six nuScenes cameras) or
            ``'quad'`` (four wide cameras, see :mod:`.camera`).
            Defaults to 'nuscenes'.
        lidar_ring (bool): Store each LiDAR point's ring index as its
            fifth value, as nuScenes does; False writes ``x, y, z,
            intensity`` (4 values a point). Defaults to True.
        progress (bool): Show a progress bar of the sweeps on stderr
            (stdout stays for the summary). Defaults to False.

    Returns:
        dict: Summary with ``scene_tokens``, ``scene_names``,
        ``descriptions``, ``sample_tokens``, counts (``num_samples``,
        ``num_sweeps``, ``num_images``, ``num_lidar_points``,
        ``num_annotations``), ``paths`` and ``seconds``.

    Raises:
        ValueError: If an argument is out of range.
        FileExistsError: If ``out_dir`` already holds a world and
            ``overwrite`` is False, or holds data this generator did not
            write.
    """
    start = time.time()
    _check_args(num_scenes, samples_per_scene, sweeps_per_sample,
                image_size, version, seed, azimuth_bins, conditions,
                camera_rig, lidar_ring)
    image_size = (int(image_size[0]), int(image_size[1]))
    if conditions is None:
        conditions = [DEFAULT_CONDITIONS[i % len(DEFAULT_CONDITIONS)]
                      for i in range(num_scenes)]
    if camera_mask_rays is None:
        # Half the image resolution resolves a 0.4 m voxel at 40 m from
        # 480x270 up; beyond 400x225 rays only cost time.
        camera_mask_rays = (int(np.clip(image_size[0] // 2, 64, 400)),
                            int(np.clip(image_size[1] // 2, 36, 225)))
    os.makedirs(out_dir, exist_ok=True)
    _prepare_out_dir(out_dir, version, overwrite)
    for folder in ('maps', osp.join('synthetic_gt', 'worlds'),
                   osp.join('lidarseg', version)):
        os.makedirs(osp.join(out_dir, folder), exist_ok=True)
    parameters = dict(num_scenes=num_scenes,
                      samples_per_scene=samples_per_scene,
                      sweeps_per_sample=sweeps_per_sample,
                      image_size=list(image_size), version=version,
                      seed=seed, azimuth_bins=azimuth_bins,
                      conditions=list(conditions),
                      camera_mask_rays=list(camera_mask_rays),
                      write_camera_labels=write_camera_labels,
                      camera_rig=camera_rig, lidar_ring=bool(lidar_ring))
    # Written first, so that an interrupted run is still recognised (and
    # replaced with overwrite=True) as a synthetic world; 'complete' marks
    # a finished one.
    _write_meta(out_dir, dict(format_version=FORMAT_VERSION,
                              complete=False, parameters=parameters))
    tables = NuScenesTables(seed)
    channels = CAMERA_RIGS[camera_rig][0] + ('LIDAR_TOP', )
    for channel in channels:
        tables.add_sensor(make_token(seed, 'sensor', channel), channel,
                          'lidar' if channel == 'LIDAR_TOP' else 'camera')
    num_sweeps = PRE_SWEEPS + (samples_per_scene - 1) * sweeps_per_sample + 1
    summary = dict(out_dir=out_dir, version=version, seed=seed,
                   scene_tokens=[], scene_names=[], descriptions=[],
                   sample_tokens=[], num_samples=0, num_sweeps=0,
                   num_images=0, num_lidar_points=0, num_annotations=0,
                   paths=dict(tables=osp.join(out_dir, version),
                              meta=osp.join(out_dir, META_PATH),
                              surroundocc=[], occ3d=[], lidarseg=[]))
    scenes_meta = []
    bar = None
    if progress:
        from mmengine.utils import ProgressBar
        bar = ProgressBar(num_scenes * num_sweeps, file=sys.stderr)
    for index in range(num_scenes):
        is_rainy, is_night = CONDITIONS[conditions[index]]
        world_rng = np.random.default_rng([seed, index, 0])
        duration = (num_sweeps - 1) * SWEEP_PERIOD_S
        world = build_world(world_rng, duration, is_rainy, is_night)
        cameras = make_camera_rig(image_size, world_rng, camera_rig)
        lidar2ego = make_lidar2ego(world_rng)
        name = f'scene-{index + 1:04d}'
        base_us = 1532402927000000 + index * 600_000_000 + seed * 1000
        local = datetime(1970, 1, 1, tzinfo=timezone.utc) + timedelta(
            microseconds=base_us) + timedelta(hours=8)
        log_token = make_token(seed, 'log', index)
        logfile = f'n015-{local:%Y-%m-%d-%H-%M-%S}+0800'
        tables.add('log', token=log_token, logfile=logfile, vehicle='n015',
                   date_captured=f'{local:%Y-%m-%d}',
                   location=_LOCATIONS[index % len(_LOCATIONS)])
        map_token = make_token(seed, 'map', index)
        reach = float(np.abs(world.ego_pose(0.0)[:2, 3]).max())
        tables.add('map', token=map_token, log_tokens=[log_token],
                   category='semantic_prior',
                   filename=_write_map(out_dir, map_token, world, reach))
        writer = SceneWriter(
            out_dir=out_dir, version=version, seed=seed, scene_index=index,
            scene_name=name, world=world, cameras=cameras,
            lidar2ego=lidar2ego, tables=tables, logfile=logfile,
            base_us=base_us, azimuth_bins=azimuth_bins,
            camera_mask_rays=camera_mask_rays,
            write_camera_labels=write_camera_labels,
            lidar_ring=bool(lidar_ring))
        recent = deque(maxlen=sweeps_per_sample)
        for sweep_index in range(num_sweeps):
            offset = sweep_index - PRE_SWEEPS
            key = offset >= 0 and offset % sweeps_per_sample == 0
            # Like nuScenes, a sweep belongs to the nearest key frame.
            sample = int(np.clip(np.floor(offset / sweeps_per_sample + 0.5),
                                 0, samples_per_scene - 1))
            sweep = writer.write_sweep(sweep_index, sweep_index
                                       * SWEEP_PERIOD_S, sample, key,
                                       num_sweeps)
            recent.append(sweep)
            if bar is not None:
                bar.update()
            if key:
                writer.write_key_frame(sample, samples_per_scene,
                                       sweep_index * SWEEP_PERIOD_S,
                                       list(recent))
        writer.finish(description=world.description, log_token=log_token)
        world_path = osp.join('synthetic_gt', 'worlds', f'{name}.json')
        with open(osp.join(out_dir, world_path), 'w') as f:
            json.dump(world_to_dict(world), f)
        scenes_meta.append(dict(name=name, token=writer.scene_token,
                                description=world.description,
                                condition=conditions[index],
                                is_rainy=is_rainy, is_night=is_night,
                                world=world_path))
        summary['scene_tokens'].append(writer.scene_token)
        summary['scene_names'].append(name)
        summary['descriptions'].append(world.description)
        summary['sample_tokens'].extend(writer.sample_tokens)
        for key, value in writer.counts.items():
            summary[key] += value
        for key, value in writer.paths.items():
            summary['paths'][key].extend(value)
    tables.write(osp.join(out_dir, version))
    summary['seconds'] = round(time.time() - start, 3)
    _write_meta(out_dir, dict(format_version=FORMAT_VERSION, complete=True,
                              parameters=parameters, scenes=scenes_meta,
                              summary=summary))
    return summary
