"""Where the label files of a sample are, and what is missing.

Shared by the nuScenes converter and the extension of mmdet3d's info
files: both link the same SurroundOcc / Occ3D label layouts and record a
missing file in the conversion report instead of stopping
(:mod:`.report`).
"""
import os.path as osp
import warnings
from typing import List, Optional

from ...fileio.safe_names import safe_file_name
from .report import ConversionReport


def rel_path(path: str, root: str) -> str:
    """Path relative to ``root`` when it lies below it, else absolute."""
    path, root = osp.abspath(path), osp.abspath(root)
    if osp.commonpath([path, root]) == root:
        return osp.relpath(path, root)
    return path


def exists_or_report(path: str, what: str, sample_token: str,
                     report: ConversionReport) -> bool:
    """Whether ``path`` exists; if not, record it under ``what``."""
    if osp.isfile(path):
        return True
    report.add(f'missing {what} (recorded as None)',
               f'sample {sample_token}: {path}')
    return False


def occ_label_paths(root: str, surroundocc_root: Optional[str],
                    occ3d_root: Optional[str], lidar_file: str,
                    scene_name: Optional[str], token: str,
                    report: ConversionReport) -> dict:
    """The SurroundOcc and Occ3D label paths of one sample.

    Args:
        root (str): nuScenes root (paths below it are written relative).
        surroundocc_root (str, optional): SurroundOcc label folder.
        occ3d_root (str, optional): Occ3D label folder.
        lidar_file (str): The key frame's file (its name names the
            SurroundOcc label).
        scene_name (str, optional): Names the Occ3D label's folder.
        token (str): Sample token.
        report (ConversionReport): Where missing files are recorded.

    Returns:
        dict: ``occ_surroundocc_path``, ``occ_occ3d_path`` (None: absent).
    """
    paths = dict(occ_surroundocc_path=None, occ_occ3d_path=None)
    if surroundocc_root is not None:
        path = osp.join(surroundocc_root, 'samples',
                        osp.basename(lidar_file) + '.npy')
        if exists_or_report(path, 'SurroundOcc label', token, report):
            paths['occ_surroundocc_path'] = rel_path(path, root)
    if occ3d_root is not None:
        path = osp.join(occ3d_root,
                        safe_file_name(scene_name, 'scene name'),
                        safe_file_name(token, 'sample token'), 'labels.npz')
        if exists_or_report(path, 'Occ3D label', token, report):
            paths['occ_occ3d_path'] = rel_path(path, root)
    return paths


def label_roots(root_path: str, surroundocc_root: Optional[str],
                occ3d_root: Optional[str]) -> List[Optional[str]]:
    """The SurroundOcc and Occ3D folders (defaults under ``root_path``);
    None, with a warning, for one that does not exist."""
    roots = []
    for given, default, name in (
            (surroundocc_root, 'nuscenes_occ', 'SurroundOcc'),
            (occ3d_root, 'gts', 'Occ3D')):
        folder = given or osp.join(root_path, default)
        if not osp.isdir(folder):
            warnings.warn(f'{name} label folder {folder} not found: its '
                          'paths are recorded as None')
            folder = None
        roots.append(folder)
    return roots
