"""Depth bins and sparse LiDAR depth maps: the one place that defines them.

A leaf module (numpy and torch only): the depth loss, the transforms that
build depth and semantic maps, the camera geometry of the lifts and
SDG-OCC's view transform all import from here, so they cannot disagree.

Conventions:

* Pixels are continuous and pixel ``i`` covers ``[i, i + 1)``: a point
  projected to image coordinate ``u`` falls in column ``floor(u)``, and in
  column ``floor(u * w / W)`` of a ``w``-wide map of a ``W``-wide image.
* ``lidar2img`` maps a working-frame point ``(x, y, z, 1)`` to ``(u * d,
  v * d, d, 1)`` with ``d`` the depth along the optical axis (see
  :mod:`projects.occ_common.transforms.frames` for the working frame).
* Where several points share a pixel (or a map cell) the nearest wins: it is
  the surface the camera sees there.
* Depth bins follow BEVDepth: ``depth_bound = (min, max, step)`` gives
  ``D = round((max - min) / step)`` bins, bin ``k`` covering
  ``[min + k * step, min + (k + 1) * step)`` and lifted at its near edge
  ``min + k * step``. OccCylindrical's 50 bins "from 1 m to 50 m" at
  d = 1 m are therefore ``(1, 51, 1)``.
* ``depth_bound = (min, max, step, 'sid')`` keeps the D bins but spaces
  them as BEVDet's ``sid=True`` (spacing-increasing discretization, Fu et
  al., DORN, CVPR 2018), which SDG-OCC's release uses: bin ``k`` is lifted
  at ``min * ((max - 1) / min) ** (k / (D - 1))`` (BEVDet's last point is
  ``max - 1`` m) and covers the depths up to the next bin's point, so the
  near bins are finer than the far ones. Every function here reads either
  form (:func:`depth_bin_coordinate`).
"""
from typing import Optional, Sequence, Tuple, Union

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from ..utils.device_path import accelerator_path
from ..utils.precision import float32_math

ArrayOrTensor = Union[np.ndarray, Tensor]


#: The depth bin spacings of a ``depth_bound``'s optional fourth entry.
DEPTH_SPACINGS = ('uniform', 'sid')


def parse_depth_bound(depth_bound: Sequence) -> Tuple[float, float, float,
                                                      str]:
    """``(dmin, dmax, step, spacing)`` of a checked depth bound.

    Args:
        depth_bound (Sequence): ``(dmin, dmax, step)`` in metres, or
            ``(dmin, dmax, step, spacing)`` with a spacing of
            :data:`DEPTH_SPACINGS` (``'uniform'`` without one).

    Returns:
        tuple: The three floats and the spacing.

    Raises:
        ValueError: If the bound is not three numbers with dmin < dmax and
            step > 0 (and, for ``'sid'``, dmin > 0 and dmax - 1 > dmin),
            or names another spacing.
    """
    if len(depth_bound) not in (3, 4):
        raise ValueError('expected depth_bound = (dmin, dmax, step) or '
                         f'(dmin, dmax, step, spacing), got {depth_bound!r}.')
    spacing = depth_bound[3] if len(depth_bound) == 4 else 'uniform'
    if spacing not in DEPTH_SPACINGS:
        raise ValueError(f'depth_bound spacing must be one of '
                         f'{DEPTH_SPACINGS}, got {depth_bound!r}.')
    dmin, dmax, step = (float(v) for v in depth_bound[:3])
    if not (step > 0 and dmax > dmin):
        raise ValueError('expected depth_bound with dmin < dmax and step > 0,'
                         f' got {depth_bound!r}.')
    if spacing == 'sid' and not (dmin > 0 and dmax - 1 > dmin):
        raise ValueError("depth_bound with 'sid' spacing needs 0 < dmin < "
                         f'dmax - 1 (log-spaced points), got {depth_bound!r}.')
    return dmin, dmax, step, spacing


def normalize_depth_bound(depth_bound: Sequence) -> tuple:
    """The bound as stored and compared: three floats, plus ``'sid'`` for
    that spacing (a ``'uniform'`` entry is dropped, so both spellings of
    uniform bins compare equal)."""
    dmin, dmax, step, spacing = parse_depth_bound(depth_bound)
    return (dmin, dmax, step) + ((spacing, ) if spacing != 'uniform' else ())


def num_depth_bins(depth_bound: Sequence) -> int:
    """Number of depth bins D = round((dmax - dmin) / step), either spacing.

    Args:
        depth_bound (Sequence): ``(dmin, dmax, step[, spacing])`` in
            metres.

    Returns:
        int: D.

    Raises:
        ValueError: From :func:`parse_depth_bound`.
    """
    dmin, dmax, step, spacing = parse_depth_bound(depth_bound)
    num = int(round((dmax - dmin) / step))
    if spacing == 'sid' and num < 2:
        raise ValueError("depth_bound with 'sid' spacing needs at least 2 "
                         f'bins, got {depth_bound!r}.')
    return num


def _sid_log_ratio(dmin: float, dmax: float) -> float:
    """``log((dmax - 1) / dmin)``: the log-depth span of BEVDet's SID."""
    return float(np.log((dmax - 1.0) / dmin))


def depth_bin_values(depth_bound: Sequence) -> Tensor:
    """Depth at which every bin is lifted: ``min + k * step``, or the
    SID points ``min * ((max - 1) / min) ** (k / (D - 1))``.

    Args:
        depth_bound (Sequence): ``(min, max, step[, spacing])`` in metres.

    Returns:
        Tensor: Depths in metres, float32. Shape (D,).
    """
    num = num_depth_bins(depth_bound)
    dmin, dmax, step, spacing = parse_depth_bound(depth_bound)
    k = torch.arange(num, dtype=torch.float32)
    if spacing == 'sid':
        return torch.exp(np.log(dmin) + k / (num - 1) *
                         _sid_log_ratio(dmin, dmax))
    return dmin + step * k


def depth_bin_coordinate(depth: Tensor, depth_bound: Sequence) -> Tensor:
    """Continuous bin index of depths: bin ``k``'s point is at ``k``.

    ``(d - min) / step`` for uniform bins; ``(D - 1) * log(d / min) /
    log((max - 1) / min)`` for SID ones (depths <= 0 give -inf there).
    ``floor`` of it is the bin a depth falls in (BEVDepth's and BEVDet's
    targets), and the linear interpolation between bins ``floor`` and
    ``floor + 1`` runs on it.

    Args:
        depth (Tensor): Depths in metres, any shape.
        depth_bound (Sequence): ``(min, max, step[, spacing])``.

    Returns:
        Tensor: Same shape and dtype as ``depth``.
    """
    num = num_depth_bins(depth_bound)
    dmin, dmax, step, spacing = parse_depth_bound(depth_bound)
    if spacing == 'sid':
        scale = (num - 1) / _sid_log_ratio(dmin, dmax)
        return torch.log(depth / dmin) * scale
    return (depth - dmin) / step


class _Ops:
    """The few functions :func:`project_nearest` needs, for numpy arrays
    (the transforms' per-sample data, single-threaded like numpy) or torch
    tensors (the models, any device): one algorithm for both."""

    def __init__(self, like) -> None:
        self.torch = isinstance(like, Tensor)
        self.device = like.device if self.torch else None

    def project(self, xyz, lidar2img):
        """``(u d, v d, d)`` of every point in every view, Shape (N, P)
        each: :func:`project_points`' homogeneous product for tensors,
        numpy's faster rotation + translation for arrays (they agree to
        float rounding)."""
        if self.torch:
            homo = torch.cat([xyz, torch.ones_like(xyz[:, :1])], 1)
            proj = torch.einsum('nij,pj->npi', lidar2img.to(xyz), homo)
            return proj[..., 0], proj[..., 1], proj[..., 2]
        cam = lidar2img[:, :3, :3] @ xyz.T + lidar2img[:, :3, 3:]
        return cam[:, 0], cam[:, 1], cam[:, 2]

    def floor(self, array):
        return (torch if self.torch else np).floor(array)

    def nonzero(self, mask):
        return mask.nonzero(as_tuple=True) if self.torch else mask.nonzero()

    def long(self, array):
        return array.long() if self.torch else array.astype(np.int64)

    def stable_argsort(self, array):
        return torch.argsort(array, stable=True) if self.torch else \
            np.argsort(array, kind='stable')

    def ones_bool(self, size):
        return torch.ones(size, dtype=torch.bool, device=self.device) \
            if self.torch else np.ones(size, dtype=bool)

    def empty_long(self):
        return torch.zeros(0, dtype=torch.long, device=self.device) \
            if self.torch else np.zeros(0, dtype=np.int64)


@float32_math
def project_points(points: Tensor,
                   lidar2img: Tensor,
                   eps: float = 1e-5) -> Tuple[Tensor, Tensor]:
    """Project working-frame points into every camera.

    Args:
        points (Tensor): Points. Shape (P, 3).
        lidar2img (Tensor): Full projections. Shape (N, 4, 4).
        eps (float): Smallest depth counted as in front of the camera.
            Defaults to 1e-5.

    Returns:
        tuple[Tensor, Tensor]: Augmented pixel ``(u, v)``, shape (N, P, 2)
        (undefined where the depth is not positive), and depth, shape (N, P).
    """
    if points.dim() != 2 or points.shape[1] != 3:
        raise ValueError(f'points must be (P, 3), got {tuple(points.shape)}')
    u_depth, v_depth, depth = _Ops(points).project(points, lidar2img)
    uv = torch.stack([u_depth, v_depth], -1) / depth.clamp(min=eps)[..., None]
    return uv, depth


def project_nearest(
    xyz: ArrayOrTensor,
    lidar2img: ArrayOrTensor,
    img_shape: Sequence[int],
    min_depth: float = 1e-3,
    max_depth: Optional[float] = None,
    map_shape: Optional[Sequence[int]] = None,
    eps: float = 1e-5
) -> Tuple[ArrayOrTensor, ...]:
    """Project points into every view and keep the nearest per map cell.

    One algorithm for numpy arrays (the transforms) and torch tensors (the
    models): the pixel and cell convention, the depth limits and the
    nearest-first choice are the same, only the projection product runs in
    each library's own form.

    Args:
        xyz (np.ndarray | Tensor): Points in the working frame.
            Shape (P, 3).
        lidar2img (np.ndarray | Tensor): Working frame to augmented
            pixels, same kind as ``xyz``. Shape (N, 4, 4).
        img_shape (Sequence[int]): Image ``(H, W)`` the pixels refer to.
        min_depth (float): Points at this depth or nearer are dropped
            (behind or on the camera). Defaults to 1e-3.
        max_depth (float, optional): Points at this depth or farther are
            dropped. Defaults to None (no limit).
        map_shape (Sequence[int], optional): ``(h, w)`` of the map; a
            stride-``s`` feature map of the image has ``(H / s, W / s)``.
            Defaults to ``img_shape`` (one cell per pixel).
        eps (float): Smallest depth divided by. Defaults to 1e-5.

    Returns:
        tuple: ``view``, ``row``, ``col`` (int64), ``depth`` (the dtype of
        ``xyz``) and ``index`` (int64, into ``xyz``) of the winning point
        of each hit cell, sorted by cell. Shapes (K,).
    """
    ops = _Ops(xyz)
    img_h, img_w = (int(v) for v in img_shape)
    map_h, map_w = (img_h, img_w) if map_shape is None else (
        int(v) for v in map_shape)
    if xyz.shape[0] == 0 or lidar2img.shape[0] == 0:
        empty = ops.empty_long()
        return empty, empty, empty, xyz[:0, 0], empty
    u_depth, v_depth, depth = ops.project(xyz, lidar2img)
    keep = depth > min_depth
    if max_depth is not None:
        keep &= depth < max_depth
    safe = depth.clip(min=eps)
    col = ops.floor(u_depth / safe * (map_w / img_w))
    row = ops.floor(v_depth / safe * (map_h / img_h))
    keep &= (col >= 0) & (col < map_w) & (row >= 0) & (row < map_h)
    view, index = ops.nonzero(keep)
    row = ops.long(row[view, index])
    col = ops.long(col[view, index])
    depth = depth[view, index]
    cell = (view * map_h + row) * map_w + col
    # By cell, then nearest first (two stable sorts, as numpy's lexsort).
    order = ops.stable_argsort(depth)
    order = order[ops.stable_argsort(cell[order])]
    first = ops.ones_bool(order.shape[0])
    first[1:] = cell[order][1:] != cell[order][:-1]
    win = order[first]
    return view[win], row[win], col[win], depth[win], index[win]


@float32_math
def nearest_depth_map(points: Tensor,
                      lidar2img: Tensor,
                      img_shape: Sequence[int],
                      map_shape: Sequence[int],
                      min_depth: float = 0.0,
                      point_mask: Optional[Tensor] = None) -> Tensor:
    """Sparse depth map of one sample: nearest return per map cell.

    The CPU's path keeps the nearest point of each cell by two stable sorts
    (:func:`project_nearest`, shared with the numpy transforms); the GPUs'
    takes the minimum depth of each cell with one ``scatter_reduce``, the
    same value without a host read of the hit count.

    Args:
        points (Tensor): Working-frame points, (x, y, z, ...).
            Shape (P, C >= 3).
        lidar2img (Tensor): Working frame to augmented pixels.
            Shape (N, 4, 4).
        img_shape (Sequence[int]): Network input ``(H, W)``.
        map_shape (Sequence[int]): Map ``(h, w)``.
        min_depth (float): Nearer returns are dropped. Defaults to 0.
        point_mask (Tensor, optional): bool, the points used (e.g. the
            key frame's). Defaults to None (all). Shape (P,).

    Returns:
        Tensor: Depth, 0 where no return. Shape (N, h, w), the dtype of
        ``lidar2img``.
    """
    if points.dim() != 2 or points.shape[1] < 3:
        raise ValueError(f'points must be (P, C >= 3), got '
                         f'{tuple(points.shape)}')
    if point_mask is not None and point_mask.shape != points.shape[:1]:
        raise ValueError(f'point_mask must be ({points.shape[0]},), got '
                         f'{tuple(point_mask.shape)}')
    if accelerator_path(points):
        return _nearest_depth_map_scatter(points, lidar2img, img_shape,
                                          map_shape, min_depth, point_mask)
    if point_mask is not None:
        points = points[point_mask]
    map_h, map_w = (int(v) for v in map_shape)
    out = lidar2img.new_zeros(lidar2img.shape[0], map_h, map_w)
    view, row, col, depth, _ = project_nearest(
        points[:, :3].to(lidar2img), lidar2img, img_shape, min_depth,
        map_shape=map_shape)
    out[view, row, col] = depth
    return out


def _nearest_depth_map_scatter(points: Tensor, lidar2img: Tensor,
                               img_shape: Sequence[int],
                               map_shape: Sequence[int], min_depth: float,
                               point_mask: Optional[Tensor],
                               eps: float = 1e-5) -> Tensor:
    """:func:`nearest_depth_map` without a host sync: the cell of every
    (view, point) pair, pairs that miss go to one extra cell, and a
    ``scatter_reduce('amin')``. Same arguments and result (the projection,
    the cell rule and the depth limits are :func:`project_nearest`'s)."""
    img_h, img_w = (int(v) for v in img_shape)
    map_h, map_w = (int(v) for v in map_shape)
    num_views = lidar2img.shape[0]
    num_cells = num_views * map_h * map_w
    xyz = points[:, :3].to(lidar2img)
    u_depth, v_depth, depth = _Ops(xyz).project(xyz, lidar2img)
    safe = depth.clip(min=eps)
    col = torch.floor(u_depth / safe * (map_w / img_w))
    row = torch.floor(v_depth / safe * (map_h / img_h))
    keep = (depth > min_depth) & (col >= 0) & (col < map_w) & (row >= 0) & \
        (row < map_h)
    if point_mask is not None:
        keep = keep & point_mask
    view = torch.arange(num_views, device=xyz.device).unsqueeze(1)
    # Where ``keep`` is False the float cell may be NaN or huge; its
    # integer is never used.
    cell = torch.where(keep, (view * map_h + row.long()) * map_w + col.long(),
                       torch.full_like(view, num_cells))
    nearest = depth.new_full((num_cells + 1, ), float('inf')).scatter_reduce_(
        0, cell.reshape(-1), depth.reshape(-1), 'amin')
    nearest = nearest[:num_cells]
    return torch.where(torch.isinf(nearest), torch.zeros_like(nearest),
                       nearest).view(num_views, map_h, map_w)


def patch_min_depth(gt_depth: Tensor, downsample: int) -> Tensor:
    """Nearest LiDAR depth of each ``downsample`` x ``downsample`` patch.

    The nearest return is kept because it is the surface the camera sees
    in that patch (farther returns are occluded or leak through edges).

    Args:
        gt_depth (Tensor): Sparse LiDAR depth map, 0 where there is no
            return. Shape (B*N, H, W).
        downsample (int): Feature stride; H and W must be multiples of it.

    Returns:
        Tensor: Minimum positive depth per patch, 0 for patches without any
        return. Shape (B*N, H / downsample, W / downsample).

    Raises:
        ValueError: If the shape is not (B*N, H, W) or H, W are not
            multiples of ``downsample``.
    """
    if gt_depth.dim() != 3:
        raise ValueError('expected gt_depth of shape (B*N, H, W), got '
                         f'{tuple(gt_depth.shape)}.')
    num, height, width = gt_depth.shape
    if height % downsample or width % downsample:
        raise ValueError(f'gt_depth size {height}x{width} is not a multiple '
                         f'of downsample={downsample}.')
    h, w = height // downsample, width // downsample
    patches = gt_depth.reshape(num, h, downsample, w, downsample)
    # Missing returns become +inf so that they never win the minimum; a
    # patch with no return at all stays inf and is mapped back to 0.
    patches = torch.where(patches > 0, patches,
                          torch.full_like(patches, float('inf')))
    nearest = patches.amin(dim=(2, 4))
    return torch.where(torch.isinf(nearest), torch.zeros_like(nearest),
                       nearest)


@float32_math
def depth_to_bins(gt_depth: Tensor,
                  downsample: int,
                  depth_bound: Sequence[float],
                  nearest_bin: bool = False) -> Tuple[Tensor, Tensor]:
    """One-hot depth-bin targets of the feature pixels, as in BEVDepth.

    Each feature pixel takes the nearest LiDAR depth d of its patch
    (:func:`patch_min_depth`) and the bin ``k = floor((d - dmin) / step)``
    (for SID bins ``floor`` of :func:`depth_bin_coordinate`, as BEVDet's
    ``sid`` targets); pixels without a return or with k outside ``[0, D)``
    (d < dmin or d >= dmin + D * step) get an all-zero row and
    ``valid = False``.

    The models lift bin ``k`` at ``dmin + k * step``
    (:func:`depth_bin_values`), so BEVDepth's ``floor`` trains every depth
    onto a point on average half a step closer (0.25 m at its 0.5 m bins,
    1.25 m at 2.5 m). ``nearest_bin`` takes the bin whose point is nearest
    instead, ``k = floor((d - dmin) / step + 0.5)``: bin ``k`` then holds
    ``[dmin + (k - 0.5) step, dmin + (k + 0.5) step)`` and the mean error
    of the lifted depth is 0.

    Args:
        gt_depth (Tensor): Sparse LiDAR depth map, 0 where there is no
            return. Shape (B*N, H, W).
        downsample (int): Feature stride.
        depth_bound (Sequence): ``(dmin, dmax, step[, spacing])`` in
            metres.
        nearest_bin (bool): Round to the nearest bin point instead of
            BEVDepth's ``floor``. Defaults to False.

    Returns:
        tuple[Tensor, Tensor]: The float one-hot targets,
        shape (B*N*h*w, D) in (B*N, h, w) row-major order, and the bool
        mask of pixels with a target, shape (B*N*h*w,).
    """
    num_bins = num_depth_bins(depth_bound)
    nearest = patch_min_depth(gt_depth, downsample).reshape(-1)
    # A pixel without a return (depth 0) is invalid whatever its coordinate
    # (-inf for SID bins); the clamp keeps the log finite.
    coord = depth_bin_coordinate(nearest.clamp(min=1e-6), depth_bound)
    bins = torch.floor(coord + (0.5 if nearest_bin else 0))
    valid = (nearest > 0) & (bins >= 0) & (bins < num_bins)
    index = torch.where(valid, bins, torch.zeros_like(bins)).long()
    onehot = F.one_hot(index, num_bins).to(gt_depth.dtype)
    onehot = onehot * valid[:, None].to(onehot.dtype)
    return onehot, valid
