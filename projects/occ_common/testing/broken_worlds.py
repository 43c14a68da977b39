"""Broken copies of a converted synthetic world: the data bugs that make
occupancy training fail silently, each made on purpose.

Every function takes the root of a *private copy* of a world converted by
``tools/create_data.py`` (e.g. the ``world_copy`` fixture) and damages it
in place the way a user's converter or preprocessing would:

* :func:`labels_in_other_frame`: the labels voxelised in the other frame
  (SurroundOcc's in the ego frame, Occ3D's in the LiDAR frame);
* :func:`transposed_extrinsics`: every ``lidar2cam`` rotation transposed;
* :func:`swapped_cameras`: two cameras' images in each other's place;
* :func:`resized_images`: the images resized after calibration;
* :func:`shifted_labels`: the label grid's origin off by whole voxels;
* :func:`flipped_labels`: the labels mirrored along one axis;
* :func:`labels_with_voxel_size`: labels voxelised at another voxel size
  than their format's (and the config's);
* :func:`missing_sweep`: one sweep file of a sample deleted;
* :func:`sweeps_without_ego_motion`: the sweeps' poses relative to the
  key frame computed as if the car stood still.

The labels are resampled voxel for voxel (the label of the voxel whose
centre the damaged grid's voxel centre falls in), so that the damaged
world is exactly what the bug would have written.
"""
import glob
import os
import os.path as osp
from typing import Callable, Iterator, Tuple

import cv2
import mmengine
import numpy as np

from ..datasets.occ_formats import OCC_FORMATS
from ..fileio.safe_pickle import load_info_file

#: Label of a voxel the damaged grid reaches outside the original one.
_OUTSIDE = -1


def _info_files(root: str) -> list:
    files = sorted(glob.glob(osp.join(root, '*_infos_*.pkl')))
    if not files:
        raise FileNotFoundError(f'no info files under {root}')
    return files


def _edit_infos(root: str, edit: Callable[[dict], None]) -> None:
    """Apply ``edit`` once to the ``images`` of every sample and
    previous-key-frame link of every info file under ``root`` (a link
    shares its frame's dicts in the pickle: each is edited once)."""
    for path in _info_files(root):
        infos = load_info_file(path)
        done = set()
        for entry in infos['data_list']:
            for frame in (entry, entry.get('prev_key_frame')):
                if frame and id(frame['images']) not in done:
                    done.add(id(frame['images']))
                    edit(frame['images'])
        mmengine.dump(infos, path)


def _samples(root: str) -> Iterator[dict]:
    """Every sample of the val info file."""
    val = [p for p in _info_files(root) if p.endswith('_infos_val.pkl')]
    if not val:
        raise FileNotFoundError(f'no *_infos_val.pkl under {root}')
    yield from load_info_file(val[0])['data_list']


def _label_files(root: str, occ_format: str) -> Iterator[Tuple[str, dict]]:
    """``(label file, its sample)`` of every labelled sample."""
    seen = set()
    for path in _info_files(root):
        for entry in load_info_file(path)['data_list']:
            rel = entry[f'occ_{occ_format}_path']
            if rel is not None and rel not in seen:
                seen.add(rel)
                yield osp.join(root, rel), entry


def _centres(shape, pc_range, voxel_size) -> np.ndarray:
    """Metric centre of every voxel. Shape (X, Y, Z, 3)."""
    index = np.stack(np.meshgrid(*[np.arange(n) for n in shape],
                                 indexing='ij'), axis=-1)
    return (np.asarray(pc_range[:3]) +
            (index + 0.5) * np.asarray(voxel_size))


def _resample(grid: np.ndarray, source_xyz: np.ndarray,
              occ_format: str) -> np.ndarray:
    """``grid``'s labels at metric positions of its own frame.

    Args:
        grid (np.ndarray): Labels (``_OUTSIDE`` allowed). Shape (X, Y, Z).
        source_xyz (np.ndarray): Where each voxel of the result takes its
            label from. Shape (X, Y, Z, 3).
        occ_format (str): The grid's format (its range and voxel size).

    Returns:
        np.ndarray: int64, ``_OUTSIDE`` where a position is off the grid.
            Shape (X, Y, Z).
    """
    spec = OCC_FORMATS[occ_format]
    index = np.floor((source_xyz - np.asarray(spec.point_cloud_range[:3])) /
                     np.asarray(spec.voxel_size)).astype(np.int64)
    inside = np.all((index >= 0) & (index < np.asarray(grid.shape)), axis=-1)
    out = np.full(grid.shape, _OUTSIDE, np.int64)
    out[inside] = grid[tuple(index[inside].T)]
    return out


def _rewrite_labels(root: str, occ_format: str,
                    move: Callable[[np.ndarray, dict], np.ndarray]) -> int:
    """Rewrite every label file with ``move(grid, sample)``, a function of
    a dense grid (``_OUTSIDE`` where empty for SurroundOcc) that returns
    the damaged grid. Returns the number of files rewritten."""
    count = 0
    for path, entry in _label_files(root, occ_format):
        if occ_format == 'surroundocc':
            rows = np.load(path)
            dense = np.full(OCC_FORMATS[occ_format].grid_size, _OUTSIDE,
                            np.int64)
            dense[tuple(rows[:, :3].T)] = rows[:, 3]
            moved = move(dense, entry)
            kept = np.argwhere(moved != _OUTSIDE)
            np.save(path, np.concatenate(
                [kept, moved[tuple(kept.T)][:, None]], axis=1).astype(
                    rows.dtype))
        else:
            with np.load(path) as npz:
                arrays = {key: npz[key] for key in npz.files}
            free = OCC_FORMATS[occ_format].empty_label
            for key, value in arrays.items():
                moved = move(value.astype(np.int64), entry)
                fill = free if key == 'semantics' else 0
                arrays[key] = np.where(moved == _OUTSIDE, fill,
                                       moved).astype(value.dtype)
            np.savez_compressed(path, **arrays)
        count += 1
    return count


def labels_in_other_frame(root: str, occ_format: str) -> int:
    """Labels voxelised in the other frame: SurroundOcc's in the ego frame
    (where Occ3D's live), Occ3D's in the LiDAR frame. Returns the number of
    label files rewritten."""
    spec = OCC_FORMATS[occ_format]
    centres = _centres(spec.grid_size, spec.point_cloud_range,
                       spec.voxel_size)

    def move(grid, entry):
        lidar2ego = np.asarray(entry['lidar_points']['lidar2ego'])
        # The damaged voxel at c (in the wrong frame) holds the label of
        # the place c names there, expressed in the labels' own frame.
        mat = np.linalg.inv(lidar2ego) if spec.frame == 'lidar' \
            else lidar2ego
        return _resample(grid, centres @ mat[:3, :3].T + mat[:3, 3],
                         occ_format)

    return _rewrite_labels(root, occ_format, move)


def shifted_labels(root: str, occ_format: str, shift=(2, 0, 0)) -> int:
    """The labels' grid origin off by ``shift`` voxels: voxel ``i`` holds
    the label of voxel ``i - shift``. Returns the files rewritten."""
    spec = OCC_FORMATS[occ_format]
    centres = _centres(spec.grid_size, spec.point_cloud_range,
                       spec.voxel_size)
    offset = np.asarray(shift) * np.asarray(spec.voxel_size)
    return _rewrite_labels(
        root, occ_format,
        lambda grid, entry: _resample(grid, centres - offset, occ_format))


def flipped_labels(root: str, occ_format: str, axis: int = 1) -> int:
    """The labels mirrored along ``axis`` (0, 1, 2 = x, y, z). Returns the
    files rewritten."""
    return _rewrite_labels(root, occ_format,
                           lambda grid, entry: np.flip(grid, axis).copy())


def labels_with_voxel_size(root: str, occ_format: str,
                           factor: float = 0.8) -> int:
    """Labels voxelised with ``factor`` times their format's voxel size in
    x and y, about the grid's centre, but stored as the format's grid.
    Returns the files rewritten."""
    spec = OCC_FORMATS[occ_format]
    size = np.asarray(spec.voxel_size) * np.array([factor, factor, 1.0])
    pc_range = np.asarray(spec.point_cloud_range, np.float64)
    low = (pc_range[:3] + pc_range[3:]) / 2 - size * np.asarray(
        spec.grid_size) / 2
    low[2] = pc_range[2]
    centres = _centres(spec.grid_size, np.concatenate([low, low]), size)
    return _rewrite_labels(
        root, occ_format,
        lambda grid, entry: _resample(grid, centres, occ_format))


def transposed_extrinsics(root: str) -> None:
    """Every camera's ``lidar2cam`` rotation transposed (a rotation written
    row- for column-major), its translation kept."""

    def edit(images):
        for image in images.values():
            mat = np.asarray(image['lidar2cam'], np.float64)
            mat[:3, :3] = mat[:3, :3].T.copy()
            image['lidar2cam'] = mat.tolist()
            if 'lidar2img' in image:
                pad = np.eye(4)
                pad[:3, :3] = np.asarray(image['cam2img'])[:3, :3]
                image['lidar2img'] = (pad @ mat).tolist()

    _edit_infos(root, edit)


def swapped_cameras(root: str, first: str = 'CAM_FRONT',
                    second: str = 'CAM_BACK') -> None:
    """The images of two cameras in each other's place (their
    calibration kept)."""

    def edit(images):
        images[first]['img_path'], images[second]['img_path'] = (
            images[second]['img_path'], images[first]['img_path'])

    _edit_infos(root, edit)


def resized_images(root: str, factor: float = 0.5) -> int:
    """Every camera image resized by ``factor`` after the conversion (its
    calibration and recorded size kept). Returns the images resized."""
    paths = sorted({
        osp.join(root, image['img_path'])
        for entry in _samples(root) for image in entry['images'].values()
    })
    for path in paths:
        image = cv2.imread(path)
        cv2.imwrite(path, cv2.resize(image, None, fx=factor, fy=factor,
                                     interpolation=cv2.INTER_AREA))
    return len(paths)


def missing_sweep(root: str, sample: int = 0, sweep: int = 3) -> str:
    """Delete sweep ``sweep`` of val sample ``sample``; returns its path."""
    entry = list(_samples(root))[sample]
    path = osp.join(root,
                    entry['lidar_sweeps'][sweep]['lidar_points']['lidar_path'])
    os.remove(path)
    return path


def sweeps_without_ego_motion(root: str) -> int:
    """Every sweep's ``sensor2lidar`` (and ``lidar2sensor``) computed from
    the mounts alone, ``inv(lidar2ego_key) @ lidar2ego_sweep``, as a
    converter that forgets the ego poses writes it: merged sweeps then
    smear whatever moved relative to the car. Returns the sweeps edited."""
    count = 0
    for path in _info_files(root):
        infos = load_info_file(path)
        done = set()
        for entry in infos['data_list']:
            key = np.asarray(entry['lidar_points']['lidar2ego'], np.float64)
            for sweep in entry.get('lidar_sweeps') or []:
                points = sweep['lidar_points']
                if id(points) in done:
                    continue
                done.add(id(points))
                still = np.linalg.inv(key) @ np.asarray(
                    points['lidar2ego'], np.float64)
                points['sensor2lidar'] = still.tolist()
                points['lidar2sensor'] = np.linalg.inv(still).tolist()
                count += 1
        mmengine.dump(infos, path)
    return count
