"""Extend mmdet3d's own nuScenes info files with the occupancy labels.

Users of mmdet3d already have ``nuscenes_infos_{train,val}.pkl`` (mmdet3d
1.x v2 layout, ``info_version`` 1.1). This reads one with the restricted
unpickler and writes the info file of this library for the same samples:

* paths become relative to the nuScenes root: mmdet3d stores bare file
  names (its dataset adds ``samples/LIDAR_TOP`` etc.), older files a
  ``data/nuscenes/...`` path; each is looked up as
  ``<root>/<mmdet3d folder>/<name>`` and then ``<root>/<name>`` (a flat
  folder, as the real sample in ``../shared`` is);
* the SurroundOcc / Occ3D label paths are added (Occ3D's folder is named
  by the scene: from the nuScenes tables when the root has them, else
  found by the sample token under the Occ3D folder);
* scene, rain and night come from the nuScenes tables (``scene.json``,
  ``sample.json``); without them they are unknown (None, False, reported);
* each image's ``height`` / ``width`` (the size its ``cam2img`` belongs
  to, which mmdet3d's infos do not record) is read from the image file's
  header, so that loading refuses an image resized after the conversion
  (``LoadMultiViewImagesOcc``) instead of projecting off by the ratio.

Missing sweeps or labels are reported and the rest kept, as in the
converter (:mod:`.report`); a missing key frame or image is an error.
"""
import json
import os
import os.path as osp
from typing import Dict, Optional, Sequence, Tuple

import numpy as np
from PIL import Image, UnidentifiedImageError

from ...fileio.safe_pickle import load_info_file
from ..info_format import camera_order, weather_flags
from .key_frame_links import link_previous_key_frames
from .label_files import label_roots, occ_label_paths
from .nuscenes_occ_converter import write_info_file
from .report import ConversionReport


def _matrix(value) -> list:
    """A matrix of the info file as a nested list."""
    return np.asarray(value, dtype=np.float64).tolist()


class _Resolver:
    """Finds the files an mmdet3d info names under the nuScenes root."""

    def __init__(self, root: str, version: str, info_file: str) -> None:
        self.root = root
        self.version = version
        self.info_file = info_file

    def find(self, name: str, folder: str) -> Optional[str]:
        """``name`` (a bare name or an mmdet3d path) relative to the root,
        trying ``<folder>/<base name>`` then ``<base name>``; None if
        neither exists."""
        base = osp.basename(name)
        for rel in (name, osp.join(folder, base), base):
            if not osp.isabs(rel) and osp.isfile(osp.join(self.root, rel)):
                return rel
        return None

    def need(self, name: str, folder: str, what: str, token: str) -> str:
        """Like :meth:`find`, but a missing file is an error."""
        rel = self.find(name, folder)
        if rel is None:
            raise FileNotFoundError(
                f'{self.info_file}: {what} of sample {token} not found: '
                f'{name} under {self.root} (tried {folder}/ and the root)')
        return rel


def image_size(path: str, what: str) -> Tuple[int, int]:
    """``(height, width)`` of an image, from its header only.

    Args:
        path (str): A JPEG / PNG file.
        what (str): File, sample and camera, for the message.

    Returns:
        tuple[int, int]: Its height and width in pixels.

    Raises:
        ValueError: If it is not an image PIL recognises.
    """
    try:
        with Image.open(path) as img:  # reads the header, not the pixels
            width, height = img.size
    except (UnidentifiedImageError, OSError) as err:
        raise ValueError(f'{what}: {path} is not a readable image ({err})'
                         ) from None
    return int(height), int(width)


def _scene_index(root: str, version: str) -> Dict[str, dict]:
    """Sample token -> its ``sample`` record with its ``scene`` record
    under ``'scene'``, from the nuScenes tables (empty if the root has
    none)."""
    tables = osp.join(root, version)
    if not (osp.isfile(osp.join(tables, 'scene.json'))
            and osp.isfile(osp.join(tables, 'sample.json'))):
        return {}
    with open(osp.join(tables, 'scene.json')) as f:
        scenes = {s['token']: s for s in json.load(f)}
    with open(osp.join(tables, 'sample.json')) as f:
        return {s['token']: dict(s, scene=scenes[s['scene_token']])
                for s in json.load(f)}


def _occ3d_index(occ3d_root: Optional[str]) -> Dict[str, str]:
    """Sample token -> scene folder of the Occ3D labels."""
    index = {}
    if occ3d_root is None:
        return index
    for scene in os.listdir(occ3d_root):
        folder = osp.join(occ3d_root, scene)
        if osp.isdir(folder):
            index.update({token: scene for token in os.listdir(folder)})
    return index


def _sweeps(entry: dict, files: _Resolver, report: ConversionReport) -> list:
    """The sweeps of one mmdet3d sample, up to the first missing file."""
    sweeps = []
    for sweep in entry.get('lidar_sweeps', []):
        points = sweep['lidar_points']
        # mmdet3d's rule: a sweep that is an earlier key frame lies in
        # samples/, the others in sweeps/.
        folder = 'samples/LIDAR_TOP' if 'samples' in points['lidar_path'] \
            else 'sweeps/LIDAR_TOP'
        rel = files.find(points['lidar_path'], folder)
        if rel is None:
            report.add('missing LiDAR sweeps (the sample keeps those before)',
                       f'sample {entry["token"]}: {len(sweeps)} kept, '
                       f'{points["lidar_path"]} missing')
            break
        out = dict(lidar_path=rel)
        for key in ('lidar2ego', 'lidar2sensor', 'sensor2lidar'):
            if key in points:
                out[key] = _matrix(points[key])
        sweeps.append(
            dict(lidar_points=out,
                 ego2global=_matrix(sweep['ego2global']),
                 timestamp=float(sweep['timestamp']),
                 sample_data_token=sweep.get('sample_data_token')))
    return sweeps


def extend_entry(entry: dict, files: _Resolver, scenes: Dict[str, dict],
                 roots: Tuple[Optional[str], Optional[str]],
                 occ3d_scenes: Dict[str, str],
                 report: ConversionReport,
                 cameras: Optional[Sequence[str]] = None) -> dict:
    """Our info entry for one sample of an mmdet3d v2 info file.

    Args:
        entry (dict): The mmdet3d ``data_list`` entry.
        files (_Resolver): Finds its files.
        scenes (dict): Sample token -> sample record with its scene (may
            be empty).
        roots (tuple): SurroundOcc and Occ3D label folders (or None).
        occ3d_scenes (dict): Sample token -> Occ3D scene folder.
        report (ConversionReport): Where problems are recorded.
        cameras (Sequence[str], optional): The cameras every sample must
            have, in order. Defaults to the entry's own
            (:func:`~..info_format.camera_order`).

    Returns:
        dict: The entry in this library's info layout.
    """
    token = entry['token']
    lidar = entry['lidar_points']
    lidar_path = files.need(lidar['lidar_path'], 'samples/LIDAR_TOP',
                            'LiDAR key frame', token)
    images = {}
    for cam in cameras or camera_order(entry['images']):
        if cam not in entry['images']:
            raise ValueError(f'{files.info_file}: sample {token} has no '
                             f'{cam} image; it has {sorted(entry["images"])}')
        image = entry['images'][cam]
        img_path = files.need(image['img_path'], f'samples/{cam}',
                              f'{cam} image', token)
        height, width = image_size(
            osp.join(files.root, img_path),
            f'{files.info_file}: {cam} image of sample {token}')
        images[cam] = dict(
            img_path=img_path,
            height=height,
            width=width,
            cam2img=_matrix(image['cam2img']),
            lidar2cam=_matrix(image['lidar2cam']),
            cam2ego=_matrix(image['cam2ego']),
            sample_data_token=image.get('sample_data_token'),
            timestamp=image.get('timestamp'))
    sample = scenes.get(token, {})
    scene = sample.get('scene')
    if scene is None:
        report.add('scene unknown (no nuScenes tables: scene None, rain / '
                   'night False)', f'sample {token}')
    description = '' if scene is None else scene['description']
    info = dict(
        token=token,
        timestamp=float(entry['timestamp']),
        scene_token=None if scene is None else scene['token'],
        scene_name=None if scene is None else scene['name'],
        scene_description=description,
        **weather_flags(description),
        prev=sample.get('prev'),
        next=sample.get('next'),
        ego2global=_matrix(entry['ego2global']),
        lidar_points=dict(
            num_pts_feats=int(lidar.get('num_pts_feats', 5)),
            lidar_path=lidar_path,
            lidar2ego=_matrix(lidar['lidar2ego'])),
        lidar_sweeps=_sweeps(entry, files, report),
        images=images,
        pts_semantic_mask_path=None)
    if entry.get('pts_semantic_mask_path'):
        rel = files.find(entry['pts_semantic_mask_path'],
                         f'lidarseg/{files.version}')
        if rel is None:
            report.add('missing lidarseg label (recorded as None)',
                       f'sample {token}: {entry["pts_semantic_mask_path"]}')
        info['pts_semantic_mask_path'] = rel
    scene_name = info['scene_name'] or occ3d_scenes.get(token)
    info.update(
        occ_label_paths(files.root, *roots, lidar_path, scene_name, token,
                        report))
    return info


def extend_mmdet3d_info_file(info_file: str,
                             root_path: str,
                             out_dir: Optional[str] = None,
                             info_prefix: str = 'nuscenes_occ',
                             surroundocc_root: Optional[str] = None,
                             occ3d_root: Optional[str] = None,
                             overwrite: bool = False) -> Tuple[str, str]:
    """Write this library's info file for an mmdet3d v2 info file.

    Args:
        info_file (str): mmdet3d's info file (``nuscenes_infos_val.pkl``).
        root_path (str): nuScenes root that its paths are relative to.
        out_dir (str, optional): Defaults to ``root_path``.
        info_prefix (str): Defaults to 'nuscenes_occ'.
        surroundocc_root (str, optional): See the converter.
        occ3d_root (str, optional): See the converter.
        overwrite (bool): Replace an existing output. Defaults to False.

    Returns:
        tuple[str, str]: The split (from the file name:
        ``nuscenes_infos_<split>.pkl``, else the name itself) and the
        written file ``<out_dir>/<info_prefix>_infos_<split>.pkl``.

    Raises:
        ValueError: Not an mmdet3d v2 info file, or a sample lacks a
            camera.
        FileNotFoundError: A key frame or image is missing.
        FileExistsError: The output exists and ``overwrite`` is False.
    """
    infos = load_info_file(info_file)
    if not isinstance(infos, dict) or not isinstance(
            infos.get('data_list'), list) or 'metainfo' not in infos:
        raise ValueError(f'{info_file}: expected an mmdet3d v2 info file '
                         'dict(metainfo=..., data_list=[...])')
    meta = infos['metainfo']
    version = meta.get('version', 'v1.0-trainval')
    stem = osp.splitext(osp.basename(info_file))[0]
    split = stem[len('nuscenes_infos_'):] \
        if stem.startswith('nuscenes_infos_') else stem
    out_dir = out_dir or root_path
    target = osp.join(out_dir, f'{info_prefix}_infos_{split}.pkl')
    if osp.exists(target) and not overwrite:
        raise FileExistsError(f'info file already exists: {target}; pass '
                              '--overwrite to replace it')
    roots = tuple(label_roots(root_path, surroundocc_root, occ3d_root))
    files = _Resolver(root_path, version, info_file)
    scenes = _scene_index(root_path, version)
    occ3d_scenes = _occ3d_index(roots[1])
    report = ConversionReport()
    # Every sample links the first one's cameras, in one order.
    cameras = camera_order(infos['data_list'][0]['images']) \
        if infos['data_list'] else ()
    entries = [
        extend_entry(entry, files, scenes, roots, occ3d_scenes, report,
                     cameras) for entry in infos['data_list']
    ]
    link_previous_key_frames(entries)
    os.makedirs(out_dir, exist_ok=True)
    write_info_file(target, entries, version, split, synthetic=False,
                    cameras=cameras,
                    extended_from=osp.basename(info_file),
                    mmdet3d_info_version=meta.get('info_version'))
    report.emit(info_file)
    return split, target
