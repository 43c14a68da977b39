"""Loading of occupancy labels and lidarseg labels.

Every loader checks what it reads and raises an error that names the file
and what was expected, instead of failing later inside numpy.
"""
from typing import Optional

import numpy as np
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS

from ..datasets.nuscenes_classes import OCC_CLASS_NAMES, lidarseg_to_occ16
from ..datasets.occ_formats import IGNORE_INDEX, OCC_FORMATS
from ..fileio.input_files import (MAX_INPUT_BYTES, load_npy, load_npz_arrays,
                                  read_input_bytes)


def read_bytes(path: str,
               what: str,
               backend_args: Optional[dict],
               kind: str = 'label') -> bytes:
    """The bytes of ``path``: a regular file within the size limit of its
    ``kind`` (:data:`~projects.occ_common.fileio.input_files.
    MAX_INPUT_BYTES`); anything else is named with ``what``."""
    return read_input_bytes(path, what, MAX_INPUT_BYTES[kind], backend_args)


def _surroundocc_rows(shape: tuple, dtype: np.dtype) -> Optional[str]:
    """What is wrong with a SurroundOcc label's declared array, or None."""
    if len(shape) != 2 or shape[1] != 4 or dtype.kind not in 'iu':
        return 'expected an integer (M, 4) array of x, y, z, label rows'
    return None


def _occ3d_array(grid: tuple):
    """The check of an Occ3D label's declared arrays (see ``_occ3d``)."""

    def check(name: str, shape: tuple, dtype: np.dtype) -> Optional[str]:
        # Class indices must be integers: boolean semantics would pass as
        # classes 0 / 1. The masks may be either.
        kinds = 'iu' if name == 'semantics' else 'iub'
        if shape != grid or dtype.kind not in kinds or dtype.itemsize > 8:
            return (f'{name} must be an integer '
                    f'{"" if name == "semantics" else "or bool "}array of '
                    f'shape {grid}')
        return None

    return check


@TRANSFORMS.register_module()
class LoadOccupancyGT(BaseTransform):
    """Load a SurroundOcc or Occ3D occupancy label as a dense grid.

    * SurroundOcc ``.npy``: (M, 4) integer rows ``x, y, z, label`` of the
      occupied voxels; unlisted voxels get 0 (``empty``), label 0
      (``noise``) becomes ``ignore_index``.
    * Occ3D ``labels.npz``: ``semantics`` (0 others .. 17 free) and the
      visibility masks ``mask_lidar`` / ``mask_camera``.

    Args:
        occ_format (str, optional): ``'surroundocc'`` or ``'occ3d'``.
            Defaults to ``results['occ_format']`` (set by the dataset).
        mask_with (str, optional): ``'camera'`` or ``'lidar'``: Occ3D voxels
            outside that visibility mask become ``ignore_index`` (the Occ3D
            camera-only protocol). Defaults to None (masks only returned).
        ignore_index (int): Label of ignored voxels. Defaults to 255.
        allow_unlabelled (bool): Let a sample whose info lists no label
            (``occ_path`` None, e.g. every sample of ``v1.0-test``) pass
            without ``gt_occ``; a listed file that is missing or broken is
            still an error. ``tools/test.py --format-only`` sets it, as
            nothing is scored there. Defaults to False (such a sample is an
            error naming it and its info file).

    Required Keys:

    - occ_path (str | None): The label file.
    - occ_format (str, optional)

    Added Keys:

    - gt_occ (np.ndarray): Shape (X, Y, Z), uint8 (not for an unlabelled
      sample with ``allow_unlabelled``).
    - mask_camera, mask_lidar (np.ndarray): Shape (X, Y, Z), bool (Occ3D).
    - occ_pc_range (np.ndarray): Shape (6,), the grid's metric range.
    - occ_voxel_size (np.ndarray): Shape (3,).
    """

    def __init__(self,
                 occ_format: Optional[str] = None,
                 mask_with: Optional[str] = None,
                 ignore_index: int = IGNORE_INDEX,
                 allow_unlabelled: bool = False) -> None:
        if occ_format is not None and occ_format not in OCC_FORMATS:
            raise ValueError(f'occ_format must be one of '
                             f'{sorted(OCC_FORMATS)}, got {occ_format!r}')
        if mask_with not in (None, 'camera', 'lidar'):
            raise ValueError("mask_with must be None, 'camera' or 'lidar', "
                             f'got {mask_with!r}')
        self.occ_format = occ_format
        self.mask_with = mask_with
        self.ignore_index = ignore_index
        self.allow_unlabelled = allow_unlabelled

    def _surroundocc(self, raw: bytes, path: str, grid) -> dict:
        if not raw:
            raise ValueError(f'SurroundOcc label {path} is empty (0 bytes)')
        # The declared shape is checked before numpy allocates it.
        arr = load_npy(raw, path, 'SurroundOcc label', _surroundocc_rows)
        xyz, label = arr[:, :3], arr[:, 3]
        if len(arr) and ((xyz < 0).any() or (xyz >= grid).any()
                         or label.min() < 0
                         or label.max() > len(OCC_CLASS_NAMES)):
            raise ValueError(
                f'SurroundOcc label {path}: voxel indices must lie in '
                f'[0, {grid}) and labels in 0..{len(OCC_CLASS_NAMES)}'
                f', got indices {xyz.min(0)}..{xyz.max(0)} and labels '
                f'{label.min()}..{label.max()}')
        gt = np.zeros(grid, dtype=np.uint8)
        label = np.where(label == 0, self.ignore_index, label)
        gt[xyz[:, 0], xyz[:, 1], xyz[:, 2]] = label
        return dict(gt_occ=gt)

    def _occ3d(self, raw: bytes, path: str, grid) -> dict:
        if not raw:
            raise ValueError(f'Occ3D label {path} is empty (0 bytes)')
        # Shapes and sizes are checked before anything is decompressed.
        out = load_npz_arrays(raw, path, 'Occ3D label',
                              ('semantics', 'mask_lidar', 'mask_camera'),
                              _occ3d_array(grid))
        sem = out['semantics']
        if sem.size and (sem.min() < 0 or sem.max() > 17):
            raise ValueError(f'Occ3D label {path}: semantics must lie in '
                             f'0..17, got {sem.min()}..{sem.max()}')
        result = dict(
            gt_occ=sem.astype(np.uint8),
            mask_lidar=out['mask_lidar'].astype(bool),
            mask_camera=out['mask_camera'].astype(bool))
        if self.mask_with is not None:
            hidden = ~result[f'mask_{self.mask_with}']
            result['gt_occ'][hidden] = self.ignore_index
        return result

    def transform(self, results: dict) -> dict:
        """Load the label of one sample.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The state with the added keys.
        """
        fmt = self.occ_format or results.get('occ_format')
        if fmt not in OCC_FORMATS:
            raise ValueError('LoadOccupancyGT needs occ_format (argument or '
                             f'results["occ_format"]), got {fmt!r}')
        spec = OCC_FORMATS[fmt]
        # The grid's geometry is the format's, labelled or not.
        results['occ_pc_range'] = np.asarray(spec.point_cloud_range)
        results['occ_voxel_size'] = np.asarray(spec.voxel_size)
        path = results.get('occ_path')
        if path is None and self.allow_unlabelled:
            return results
        if path is None:
            raise ValueError(
                f'sample {results.get("token", "?")} has no {fmt} occupancy '
                f'label in {results.get("ann_file", "its info file")} (a '
                'split without labels runs with tools/test.py --format-only)')
        raw = read_bytes(path, f'{fmt} occupancy label', None)
        # Python ints: numpy 2 would print np.int64(200) in the messages.
        grid = tuple(int(g) for g in spec.grid_size)
        loaded = self._surroundocc(raw, path, grid) if fmt == 'surroundocc' \
            else self._occ3d(raw, path, grid)
        results.update(loaded)
        return results

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}(occ_format={self.occ_format!r}, '
                f'mask_with={self.mask_with!r}, '
                f'ignore_index={self.ignore_index}, '
                f'allow_unlabelled={self.allow_unlabelled})')


@TRANSFORMS.register_module()
class LoadLidarSegLabels(BaseTransform):
    """Load nuScenes-lidarseg point labels as the 16 occupancy classes.

    The ``.bin`` holds one uint8 raw class (0..31) per key-frame point; it
    is mapped with the lidarseg challenge table to 1..16, and the classes
    the challenge ignores (``noise`` etc.) become ``ignore_index``, so that
    point labels share the label values of the occupancy grids. Apply it
    after the key frame is loaded and before sweeps are merged.

    Args:
        ignore_index (int): Label of ignored points. Defaults to 255.
        optional (bool): A sample whose info has no lidarseg label (the
            converter found no nuScenes-lidarseg) passes unchanged, and
            ``PointsToSemanticMaps`` takes its labels from the occupancy
            grid. A label the info names but that is missing stays an
            error. Defaults to False (every sample must have one).
        backend_args (dict, optional): mmengine file backend arguments.

    Required Keys:

    - pts_semantic_mask_path (str | None)
    - points (BasePoints, optional): Key frame, to check the count.
    - points_kept_rows (np.ndarray, optional): Shape (P_file,), bool: the
      rows of the key-frame file ``LoadOccPointsFromFile`` kept (it drops
      points with NaN / inf values); the labels of the others are dropped
      too.

    Added Keys:

    - pts_semantic_mask (np.ndarray): Shape (P,), int64.
    """

    def __init__(self,
                 ignore_index: int = IGNORE_INDEX,
                 optional: bool = False,
                 backend_args: Optional[dict] = None) -> None:
        self.ignore_index = ignore_index
        self.optional = optional
        self.backend_args = backend_args

    def transform(self, results: dict) -> dict:
        """Load the labels of one sample.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The state with ``pts_semantic_mask``.
        """
        path = results.get('pts_semantic_mask_path')
        if path is None and self.optional:
            return results
        if path is None:
            raise ValueError(
                f'sample {results.get("token", "?")} has no lidarseg label in'
                f' {results.get("ann_file", "its info file")}')
        raw = read_bytes(path, 'lidarseg label', self.backend_args)
        labels = lidarseg_to_occ16(np.frombuffer(raw, np.uint8), path)
        kept = results.get('points_kept_rows')
        if kept is not None:
            if len(labels) != len(kept):
                raise ValueError(
                    f'lidarseg label {path} has {len(labels)} labels, '
                    f'expected one per point of {results.get("lidar_path")} '
                    f'({len(kept)})')
            labels = labels[kept]
        if 'points' in results and len(labels) != len(results['points']):
            raise ValueError(
                f'lidarseg label {path} has {len(labels)} labels, expected '
                f'one per key-frame point ({len(results["points"])} in '
                f'{results.get("lidar_path")}); load labels before merging '
                'sweeps')
        labels = labels.astype(np.int64)
        labels[labels == 0] = self.ignore_index
        results['pts_semantic_mask'] = labels
        return results

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}(ignore_index={self.ignore_index}'
                f', optional={self.optional})')
