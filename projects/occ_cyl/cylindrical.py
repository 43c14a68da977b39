"""The cylindrical volume ``[R, Theta, Z]`` of OccCylindrical (eqs. 4, 6-7).

The conversion functions are shared with the camera geometry and live in
``projects.occ_common.models.layers``; they are re-exported here.
"""
import math
from typing import Sequence, Tuple

import torch
from torch import Tensor

from projects.occ_common.models.layers import (cartesian_to_cylindrical,
                                               create_frustum,
                                               cylindrical_to_cartesian,
                                               frustum_to_lidar)
from projects.occ_common.utils.device_path import accelerator_path

__all__ = [
    'CylinderGrid', 'cartesian_to_cylindrical', 'cylindrical_to_cartesian',
    'pseudo_point_voxels'
]


#: How :meth:`CylinderGrid.for_box` sizes the radius to an occupancy box.
RADIUS_FITS = ('inscribed', 'circumscribed')


class CylinderGrid:
    """A uniform grid over radius, azimuth and height.

    Voxel ``(i, j, k)`` covers ``r in [r_min + i * dr, r_min + (i + 1) * dr)``
    and likewise for ``theta`` and ``z``. When the azimuth range is the full
    circle the azimuth index wraps, so ``theta = pi`` falls in voxel 0 like
    ``theta = -pi``.

    Points outside the ranges are either clamped into the border voxel of
    each axis they leave (``clamp=True``: PointOcc's and Cylinder3D's
    practice, ``np.clip(xyz_pol, min_bound, max_bound - 1e-3)``; a point at
    80 m lands in the outermost ring) or belong to no voxel (index -1, so
    the voxel pooling drops them). The occupancy head samples the planes
    the same way: with ``clamp`` the output voxels beyond the radius take
    the border ring, without it :meth:`covers_box` must hold.

    OccCylindrical builds one grid (:meth:`for_box` of its occupancy range)
    and hands the same object to every module that needs it.

    Args:
        shape (Sequence[int]): Cells ``(R, Theta, Z)`` (the occupancy
            grid's ``(X, Y, Z)`` is ``occ_shape``).
        cyl_range (Sequence[float]): ``(r_min, theta_min, z_min, r_max,
            theta_max, z_max)``, radii and heights in metres, angles in
            radians.
        clamp (bool): Clamp outside points into the border voxels instead
            of dropping them. Defaults to False.
    """

    def __init__(self,
                 shape: Sequence[int],
                 cyl_range: Sequence[float],
                 clamp: bool = False) -> None:
        if len(shape) != 3 or min(int(s) for s in shape) < 1:
            raise ValueError('CylinderGrid: shape must be three positive '
                             f'sizes (R, Theta, Z), got {shape}')
        if len(cyl_range) != 6:
            raise ValueError('CylinderGrid: cyl_range must be (r_min, '
                             'theta_min, z_min, r_max, theta_max, z_max), '
                             f'got {cyl_range}')
        lo, hi = list(map(float, cyl_range[:3])), list(map(float,
                                                           cyl_range[3:]))
        if any(h <= m for m, h in zip(lo, hi)) or lo[0] < 0:
            raise ValueError('CylinderGrid: cyl_range needs 0 <= r_min and '
                             f'min < max on every axis, got {cyl_range}')
        if hi[1] - lo[1] > 2 * math.pi + 1e-6:
            raise ValueError('CylinderGrid: the azimuth range exceeds 2*pi: '
                             f'{cyl_range}')
        self.shape = tuple(int(s) for s in shape)
        self.cyl_range = tuple(lo + hi)
        self.full_circle = abs(hi[1] - lo[1] - 2 * math.pi) < 1e-4
        self.clamp = bool(clamp)

    @classmethod
    def for_box(cls,
                box: Sequence[float],
                shape: Sequence[int],
                radius: str = 'circumscribed',
                clamp: bool = False) -> 'CylinderGrid':
        """The full-circle cylinder of an occupancy box.

        Args:
            box (Sequence[float]): ``(x_min, y_min, z_min, x_max, y_max,
                z_max)``, metres.
            shape (Sequence[int]): Cells ``(R, Theta, Z)``.
            radius (str): ``'circumscribed'``: the radius reaches the box's
                farthest corner (:meth:`covering`); ``'inscribed'``: the
                radius is the distance from the axis to the nearest box
                side, 50 m for ``x, y in [-50, 50]`` as PointOcc's
                ``[0, 50]``. Defaults to 'circumscribed'.
            clamp (bool): See the class. Defaults to False.

        Returns:
            CylinderGrid: The grid, azimuth ``[-pi, pi]``, the box's height.
        """
        if radius not in RADIUS_FITS:
            raise ValueError(f'CylinderGrid: radius must be one of '
                             f'{RADIUS_FITS}, got {radius!r}')
        if radius == 'circumscribed':
            grid = cls.covering(box, shape)
            return cls(grid.shape, grid.cyl_range, clamp)
        x0, y0, z0, x1, y1, z1 = (float(v) for v in box)
        r_max = min(-x0, x1, -y0, y1)
        if r_max <= 0:
            raise ValueError('CylinderGrid: an inscribed radius needs the '
                             f'axis inside the box, got {tuple(box)}')
        return cls(shape, (0.0, -math.pi, z0, r_max, math.pi, z1), clamp)

    @classmethod
    def covering(cls,
                 box: Sequence[float],
                 shape: Sequence[int],
                 margin: float = 0.01) -> 'CylinderGrid':
        """The full-circle cylinder that holds every point of a box.

        Its radius reaches the box's farthest corner, e.g.
        ``(50^2 + 50^2)^0.5 = 70.71`` m for ``x, y in [-50, 50]``, plus
        ``margin`` against rounding; its height is the box's and its
        azimuth ``[-pi, pi]``.

        Args:
            box (Sequence[float]): ``(x_min, y_min, z_min, x_max, y_max,
                z_max)``, metres.
            shape (Sequence[int]): Cells ``(R, Theta, Z)``.
            margin (float): Metres added to the radius. Defaults to 0.01.

        Returns:
            CylinderGrid: The grid; :meth:`covers_box` holds for ``box``.
        """
        x0, y0, z0, x1, y1, z1 = (float(v) for v in box)
        r_max = (max(-x0, x1)**2 + max(-y0, y1)**2)**0.5 + margin
        return cls(shape, (0.0, -math.pi, z0, r_max, math.pi, z1))

    @property
    def num_voxels(self) -> int:
        """``R * Theta * Z``."""
        r, t, z = self.shape
        return r * t * z

    @property
    def voxel_size(self) -> Tuple[float, float, float]:
        """``(dr, dtheta, dz)``."""
        return tuple((self.cyl_range[i + 3] - self.cyl_range[i]) /
                     self.shape[i] for i in range(3))

    def voxel_coords(self, cyl: Tensor) -> Tuple[Tensor, Tensor]:
        """Integer voxel coordinates of cylindrical points.

        Args:
            cyl (Tensor): ``(r, theta, z)``. Shape (..., 3).

        Returns:
            tuple[Tensor, Tensor]: ``(i, j, k)`` as int64, shape (..., 3)
            (meaningless where outside), and the inside mask, shape (...):
            with ``clamp`` every finite point is inside.
        """
        lo = cyl.new_tensor(self.cyl_range[:3])
        size = cyl.new_tensor(self.voxel_size)
        finite = torch.isfinite(cyl).all(dim=-1)
        # NaN would cast to an arbitrary integer: park it at 0, outside.
        scaled = torch.where(finite[..., None], (cyl - lo) / size,
                             torch.zeros_like(cyl))
        coords = torch.floor(scaled).long()
        shape = torch.tensor(self.shape, device=cyl.device)
        if self.full_circle:
            coords[..., 1] = coords[..., 1] % self.shape[1]
        if self.clamp:
            # Index clamping equals PointOcc's clip to [min, max - 1e-3]
            # followed by floor, up to points in the last millimetre.
            coords = torch.minimum(coords.clamp(min=0), shape - 1)
            return coords, finite
        inside = ((coords >= 0) & (coords < shape)).all(dim=-1) & finite
        return coords, inside

    def flat_index(self, cyl: Tensor, batch_idx: Tensor = None) -> Tensor:
        """Flat voxel index ``((b * R + i) * Theta + j) * Z + k``.

        Args:
            cyl (Tensor): ``(r, theta, z)``. Shape (..., 3).
            batch_idx (Tensor, optional): Sample of each point, broadcast to
                shape (...). Defaults to sample 0.

        Returns:
            Tensor: int64 index, -1 outside the grid. Shape (...).
        """
        coords, inside = self.voxel_coords(cyl)
        _, nt, nz = self.shape
        flat = (coords[..., 0] * nt + coords[..., 1]) * nz + coords[..., 2]
        if batch_idx is not None:
            flat = flat + batch_idx * self.num_voxels
        return torch.where(inside, flat, torch.full_like(flat, -1))

    def occupied(self, flat: Tensor) -> Tuple[Tensor, Tensor]:
        """The occupied voxels of flat indices, and each point's row.

        The voxel pooling keeps one feature row per occupied voxel instead
        of a dense ``(V, C)`` volume: at 480 x 368 x 32 cells a dense
        volume of 64 channels is 1.4 GB, the ~0.56 M occupied voxels of the
        camera cloud are 0.14 GB. Indices only (no gradient flows here).

        Args:
            flat (Tensor): From :meth:`flat_index`, -1 outside.
                Shape (...).

        Returns:
            tuple[Tensor, Tensor]: The sorted flat indices of the occupied
            voxels, shape (U,), and each point's row among them (-1 for
            points outside), int64, the shape of ``flat``.
        """
        if not accelerator_path(flat):
            voxels, rows = torch.unique(flat, return_inverse=True)
            if voxels.numel() and int(voxels[0]) < 0:
                return voxels[1:], rows - 1
            return voxels, rows
        # GPUs: points outside (-1) take a key past every voxel's, and one
        # such key is always appended: it is always the last unique value
        # and is cut off without reading on the host whether one occurred
        # (a sync). On the CPU the extra passes cost ~1.5x the unique.
        past = torch.iinfo(torch.long).max
        keys = torch.where(flat < 0, torch.full_like(flat, past), flat)
        voxels, rows = torch.unique(
            torch.cat([keys.reshape(-1), keys.new_full((1, ), past)]),
            return_inverse=True)
        rows = rows[:-1].view_as(flat)
        return voxels[:-1], torch.where(flat < 0, torch.full_like(rows, -1),
                                        rows)

    def occupied_padded(self, flat: Tensor
                        ) -> Tuple[Tensor, Tensor, Tensor]:
        """:meth:`occupied` in a list as long as the points: no size that
        depends on the data.

        ``torch.unique`` returns as many voxels as are occupied, a size the
        host must read (a graph break under ``torch.compile``, and no CUDA
        graph can hold it). Here the voxels fill the first rows of a list
        of one row per point, in the same (sorted) order, and the rows
        after them are padding: a sort, a cumulative sum and two scatters.

        Args:
            flat (Tensor): From :meth:`flat_index`, -1 outside.
                Shape (...).

        Returns:
            tuple[Tensor, Tensor, Tensor]: The flat indices, Shape (P,)
            with P = ``flat.numel()``: those of :meth:`occupied` first,
            then padding (meaningless values); each point's row, -1 for
            points outside, the shape of ``flat``: equal to
            :meth:`occupied`'s; and which rows hold a voxel, bool,
            Shape (P,).
        """
        past = torch.iinfo(torch.long).max
        keys = torch.where(flat < 0, torch.full_like(flat, past),
                           flat).reshape(-1)
        ordered, order = torch.sort(keys)
        first = torch.ones_like(ordered, dtype=torch.bool)
        first[1:] = ordered[1:] != ordered[:-1]
        run = first.cumsum(0) - 1
        rows = torch.empty_like(run).scatter_(0, order, run).view_as(flat)
        # Every point of a run writes the same key into its row.
        voxels = torch.full_like(keys, past).scatter_(0, run, ordered)
        return (voxels, torch.where(flat < 0, torch.full_like(rows, -1),
                                    rows), voxels != past)

    def unravel(self, flat: Tensor) -> Tensor:
        """``(b, i, j, k)`` of flat indices ``((b * R + i) * Theta + j) * Z
        + k``.

        Args:
            flat (Tensor): Non-negative int64 indices. Shape (U,).

        Returns:
            Tensor: int64. Shape (U, 4).
        """
        r_cells, t_cells, z_cells = self.shape
        k = flat % z_cells
        rest = flat // z_cells
        j = rest % t_cells
        rest = rest // t_cells
        return torch.stack([rest // r_cells, rest % r_cells, j, k], dim=-1)

    def normalize(self, cyl: Tensor) -> Tensor:
        """Map the ranges to ``[-1, 1]`` (``grid_sample``, corners excluded).

        Args:
            cyl (Tensor): ``(r, theta, z)``. Shape (..., 3).

        Returns:
            Tensor: Normalised coordinates. Shape (..., 3).
        """
        lo = cyl.new_tensor(self.cyl_range[:3])
        hi = cyl.new_tensor(self.cyl_range[3:])
        return (cyl - lo) / (hi - lo) * 2 - 1

    def covers_box(self, box: Sequence[float]) -> bool:
        """Whether every point of an axis-aligned box lies in the cylinder.

        The farthest points of a box are its corners (``50 * sqrt(2)`` m for
        ``x, y in [-50, 50]``), the nearest the point closest to the axis.

        Args:
            box (Sequence[float]): ``(x_min, y_min, z_min, x_max, y_max,
                z_max)``.

        Returns:
            bool: True when radius and height are covered and the azimuth
            range is the full circle (a partial sector is reported as not
            covering, which is conservative).
        """
        x0, y0, z0, x1, y1, z1 = map(float, box)
        r_min, t_min, zc_min, r_max, t_max, zc_max = self.cyl_range
        far = max(math.hypot(x, y) for x in (x0, x1) for y in (y0, y1))
        near = math.hypot(
            0.0 if x0 <= 0 <= x1 else min(abs(x0), abs(x1)),
            0.0 if y0 <= 0 <= y1 else min(abs(y0), abs(y1)))
        return (r_min <= near and far <= r_max and zc_min <= z0
                and z1 <= zc_max and self.full_circle)

    def __repr__(self) -> str:
        return (f'{type(self).__name__}(shape={self.shape}, '
                f'cyl_range={self.cyl_range}, clamp={self.clamp})')


def pseudo_point_voxels(cylinder: CylinderGrid, lidar2img: Tensor,
                        input_shape: Sequence[int], feat_shape: Sequence[int],
                        depth_bound: Sequence[float]) -> Tuple[int, int]:
    """Pseudo points and the voxels they occupy: Table VI's "density".

    Every depth bin of every feature cell of every view is one pseudo point
    (as the model lifts them); the count after the per-voxel max pool is
    the number of distinct voxels they fall in. It depends on the cameras,
    the bins and the cylinder only.

    Args:
        cylinder (CylinderGrid): The model's cylinder.
        lidar2img (Tensor): Projections of the views. Shape (N, 4, 4).
        input_shape (Sequence[int]): Padded input ``(H, W)``.
        feat_shape (Sequence[int]): Feature map ``(h, w)``.
        depth_bound (Sequence[float]): ``(min, max, step)`` of the bins.

    Returns:
        tuple[int, int]: Points before and occupied voxels after pooling.
    """
    frustum = create_frustum(input_shape, feat_shape, depth_bound)
    points = frustum_to_lidar(frustum, lidar2img[None].float())
    flat = cylinder.flat_index(cartesian_to_cylindrical(points))
    return flat.numel(), cylinder.occupied(flat)[0].numel()
