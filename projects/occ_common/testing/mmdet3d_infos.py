"""mmdet3d v2 info files made from this library's, for the tests of the
``--from-mmdet3d-info`` conversion and of the demo's single-sample path."""
import os.path as osp
from typing import List

import mmengine


def mmdet3d_entry(entry: dict) -> dict:
    """One sample of this library's info file as mmdet3d 1.x writes it.

    Bare file names for the key frame, images and lidarseg, sweeps as
    ``data/nuscenes/sweeps/...`` paths, no scene keys, no image sizes and
    no labels, as ``tools/create_data.py nuscenes`` of mmdet3d writes them.

    Args:
        entry (dict): A ``data_list`` entry of ``tools/create_data.py``.

    Returns:
        dict: The mmdet3d v2 entry.
    """
    return dict(
        sample_idx=entry['sample_idx'], token=entry['token'],
        timestamp=entry['timestamp'], ego2global=entry['ego2global'],
        lidar_points=dict(
            num_pts_feats=5,
            lidar_path=osp.basename(entry['lidar_points']['lidar_path']),
            lidar2ego=entry['lidar_points']['lidar2ego']),
        lidar_sweeps=[
            dict(lidar_points=dict(
                lidar_path='data/nuscenes/' + s['lidar_points']['lidar_path'],
                lidar2ego=s['lidar_points']['lidar2ego'],
                lidar2sensor=s['lidar_points']['lidar2sensor'],
                sensor2lidar=s['lidar_points']['sensor2lidar']),
                 ego2global=s['ego2global'],
                 timestamp=s['timestamp'],
                 sample_data_token=s['sample_data_token'])
            for s in entry['lidar_sweeps']
        ],
        images={
            cam: dict(img_path=osp.basename(i['img_path']),
                      **{k: i[k] for k in ('cam2img', 'lidar2cam',
                                           'cam2ego', 'timestamp',
                                           'sample_data_token')})
            for cam, i in entry['images'].items()
        },
        pts_semantic_mask_path=osp.basename(entry['pts_semantic_mask_path']),
        instances=[])


def write_mmdet3d_info_file(path: str, entries: List[dict],
                            version: str = 'v1.0-mini') -> str:
    """Write :func:`mmdet3d_entry` of each entry as an mmdet3d v2 info
    file (``info_version`` 1.1); returns ``path``."""
    mmengine.dump(dict(metainfo=dict(version=version, info_version='1.1',
                                     dataset='nuscenes'),
                       data_list=[mmdet3d_entry(e) for e in entries]), path)
    return path
