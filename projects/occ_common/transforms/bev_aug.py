"""BEV data augmentation (flip / rotate / scale) of points, labels, cameras.

One 4x4 matrix ``bda`` (BEVDet's "BEV data augmentation", Huang et al.
2021, Sec. 3.3) maps the working frame before the augmentation to the one
after: ``bda = flip @ scale @ rot_z``. Points are mapped by it, every
``lidar2*`` matrix becomes ``lidar2X @ inv(bda)`` (so that projections of
the moved points into the unchanged images stay the same), and the
occupancy grid is remapped:

* flips of a symmetric axis and multiples of 90 degrees on a square,
  centred grid map voxels onto voxels: the grid is permuted exactly;
* any other angle or a scale != 1 resamples the grid by nearest neighbour
  (each target voxel centre is mapped back by ``inv(bda)`` and takes the
  label of the voxel it lands in; targets landing outside the source grid
  get ``ignore_index``, visibility masks get False). Thin structures can
  lose or gain a voxel there, so use such angles / scales knowingly.
"""
import math
from typing import Sequence

import numpy as np
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS

from ..datasets.occ_formats import IGNORE_INDEX
from .frames import change_working_frame

_GRID_KEYS = ('gt_occ', 'mask_camera', 'mask_lidar')


def bda_matrix(angle_deg: float, scale: float, flip_x: bool,
               flip_y: bool) -> np.ndarray:
    """The 4x4 BEV augmentation ``flip @ scale @ rot_z``.

    Args:
        angle_deg (float): Counter-clockwise rotation about z, degrees.
        scale (float): Isotropic scale.
        flip_x (bool): Negate x.
        flip_y (bool): Negate y.

    Returns:
        np.ndarray: Shape (4, 4).
    """
    theta = math.radians(angle_deg)
    rot = np.eye(4)
    rot[:2, :2] = [[math.cos(theta), -math.sin(theta)],
                   [math.sin(theta), math.cos(theta)]]
    flip = np.diag([-1.0 if flip_x else 1.0, -1.0 if flip_y else 1.0, 1, 1])
    return flip @ np.diag([scale, scale, scale, 1.0]) @ rot


def resample_grid(grid: np.ndarray, bda: np.ndarray, pc_range: np.ndarray,
                  voxel_size: np.ndarray, fill) -> np.ndarray:
    """Nearest-neighbour remap of a voxel grid under ``bda``.

    Args:
        grid (np.ndarray): Shape (X, Y, Z).
        bda (np.ndarray): Shape (4, 4), old frame -> new frame.
        pc_range (np.ndarray): Shape (6,), the grid's metric range.
        voxel_size (np.ndarray): Shape (3,).
        fill: Value of targets that map outside the grid.

    Returns:
        np.ndarray: Shape (X, Y, Z), same dtype.
    """
    shape = np.asarray(grid.shape)
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in shape],
                               indexing='ij'), -1).reshape(-1, 3)
    centres = pc_range[:3] + (idx + 0.5) * voxel_size
    inv = np.linalg.inv(bda)
    src = centres @ inv[:3, :3].T + inv[:3, 3]
    # Voxel centres map onto voxel centres for exact cases; the epsilon
    # keeps float error from pushing them across a face.
    src_idx = np.floor((src - pc_range[:3]) / voxel_size + 1e-6).astype(int)
    inside = np.all((src_idx >= 0) & (src_idx < shape), axis=1)
    out = np.full(grid.size, fill, dtype=grid.dtype)
    s = src_idx[inside]
    out[inside] = grid[s[:, 0], s[:, 1], s[:, 2]]
    return out.reshape(grid.shape)


def _exact_permutation(grid: np.ndarray, quarter_turns: int, flip_x: bool,
                       flip_y: bool) -> np.ndarray:
    """The exact remap for quarter turns then flips on a centred grid."""
    out = np.rot90(grid, k=quarter_turns, axes=(0, 1))
    if flip_x:
        out = out[::-1]
    if flip_y:
        out = out[:, ::-1]
    return np.ascontiguousarray(out)


@TRANSFORMS.register_module()
class OccBEVAug(BaseTransform):
    """Random BEV flip / rotation / scale, consistent across modalities.

    Training draws an angle ``U(rot_range)`` (plus a random multiple of 90
    degrees if ``rot90``), a scale ``U(scale_range)`` and flips of x / y
    with their probabilities; ``test_mode`` keeps the identity (but still
    adds ``bda_matrix``). See the module docstring for how the grid is
    remapped.

    Args:
        rot_range (Sequence[float]): Angle range, degrees.
            Defaults to (0.0, 0.0).
        rot90 (bool): Add k * 90 degrees, k uniform in 0..3.
            Defaults to False.
        scale_range (Sequence[float]): Defaults to (1.0, 1.0).
        flip_x_prob (float): Probability to negate x. Defaults to 0.5.
        flip_y_prob (float): Probability to negate y. Defaults to 0.5.
        ignore_index (int): Label of resampled voxels from outside the
            grid. Defaults to 255.
        test_mode (bool): No augmentation. Defaults to False.

    Required Keys:

    - points (BasePoints | np.ndarray, optional)
    - gt_occ, mask_camera, mask_lidar (np.ndarray, optional): (X, Y, Z).
    - occ_pc_range, occ_voxel_size (np.ndarray): with ``gt_occ``.
    - lidar2cam, lidar2ego, cam2img, img_aug_matrix (np.ndarray, optional)

    Modified Keys:

    - points, gt_occ, mask_camera, mask_lidar, lidar2cam, lidar2ego,
      lidar2img

    Added Keys:

    - bda_matrix (np.ndarray): Shape (4, 4), composed with any earlier one.
    - bda_params (dict): ``rotate`` (degrees), ``scale``, ``flip_x``,
      ``flip_y``.
    """

    def __init__(self,
                 rot_range: Sequence[float] = (0.0, 0.0),
                 rot90: bool = False,
                 scale_range: Sequence[float] = (1.0, 1.0),
                 flip_x_prob: float = 0.5,
                 flip_y_prob: float = 0.5,
                 ignore_index: int = IGNORE_INDEX,
                 test_mode: bool = False) -> None:
        if len(rot_range) != 2 or rot_range[0] > rot_range[1]:
            raise ValueError(f'rot_range must be (low, high), got {rot_range}')
        if len(scale_range) != 2 or not 0 < scale_range[0] <= scale_range[1]:
            raise ValueError('scale_range must be (low, high) > 0, got '
                             f'{scale_range}')
        self.rot_range = tuple(rot_range)
        self.rot90 = rot90
        self.scale_range = tuple(scale_range)
        self.flip_x_prob = flip_x_prob
        self.flip_y_prob = flip_y_prob
        self.ignore_index = ignore_index
        self.test_mode = test_mode

    def sample_params(self) -> dict:
        """Draw one augmentation.

        Returns:
            dict: ``rotate`` (degrees), ``scale``, ``flip_x``, ``flip_y``.
        """
        if self.test_mode:
            return dict(rotate=0.0, scale=1.0, flip_x=False, flip_y=False)
        angle = float(np.random.uniform(*self.rot_range))
        if self.rot90:
            angle += 90.0 * np.random.randint(4)
        return dict(
            rotate=angle,
            scale=float(np.random.uniform(*self.scale_range)),
            flip_x=bool(np.random.rand() < self.flip_x_prob),
            flip_y=bool(np.random.rand() < self.flip_y_prob))

    def apply(self, results: dict, params: dict) -> dict:
        """Apply a given augmentation (deterministic; used by tests).

        Args:
            results (dict): Pipeline state.
            params (dict): As returned by :meth:`sample_params`.

        Returns:
            dict: The augmented state.
        """
        bda = bda_matrix(params['rotate'], params['scale'], params['flip_x'],
                         params['flip_y'])
        change_working_frame(results, bda)
        if 'gt_occ' in results:
            self._remap_grids(results, bda, params)
        results['bda_matrix'] = bda @ results.get('bda_matrix', np.eye(4))
        results['bda_params'] = params
        return results

    def _remap_grids(self, results: dict, bda: np.ndarray,
                     params: dict) -> None:
        pc_range = np.asarray(results['occ_pc_range'], dtype=np.float64)
        voxel = np.asarray(results['occ_voxel_size'], dtype=np.float64)
        shape = results['gt_occ'].shape
        lo, hi = pc_range[:3], pc_range[3:]
        quarter = params['rotate'] / 90.0
        centred = np.allclose(lo[:2], -hi[:2])
        exact = (params['scale'] == 1.0 and quarter == round(quarter)
                 and centred
                 and (round(quarter) % 2 == 0 or
                      (shape[0] == shape[1] and voxel[0] == voxel[1])))
        for key in _GRID_KEYS:
            if key not in results:
                continue
            grid = results[key]
            if exact:
                results[key] = _exact_permutation(grid,
                                                  int(round(quarter)) % 4,
                                                  params['flip_x'],
                                                  params['flip_y'])
            else:
                fill = self.ignore_index if key == 'gt_occ' else False
                results[key] = resample_grid(grid, bda, pc_range, voxel,
                                             fill)

    def transform(self, results: dict) -> dict:
        """Draw and apply an augmentation.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The augmented state.
        """
        return self.apply(results, self.sample_params())

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}(rot_range={self.rot_range}, '
                f'rot90={self.rot90}, scale_range={self.scale_range}, '
                f'flip_x_prob={self.flip_x_prob}, '
                f'flip_y_prob={self.flip_y_prob}, '
                f'test_mode={self.test_mode})')
