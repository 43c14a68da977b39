"""Point <-> voxel transfers of SPVCNN's point-voxel convolution.

Implements the two bridges of SPVConv (Tang et al., ECCV 2020, "Searching
Efficient 3D Architectures with Sparse Point-Voxel Convolution",
sec. 3.2): points to voxels by averaging the points of each voxel, and
voxels to points by trilinear interpolation of the eight nearest voxel
centres. Both work on any device and are differentiable with respect to
the features.
"""
import itertools
from typing import NamedTuple, Optional, Sequence, Tuple

import torch
import torch.nn.functional as F
from torch import Tensor

from ...utils.device_path import accelerator_path
from .rulebook import CoordIndex, delinearize, in_bounds, linearize
from .sparse_tensor import SparseTensor

#: The eight corner offsets ``(c_z, c_y, c_x)``, corner ``4 c_z + 2 c_y +
#: c_x``. Shape (8, 3).
_CORNERS = tuple(itertools.product((0, 1), repeat=3))


def scatter_mean(src: Tensor, index: Tensor, num_rows: int) -> Tensor:
    """Average the rows of ``src`` that share an ``index``.

    Args:
        src (Tensor): Values. Shape (N, C).
        index (Tensor): Target row of each value, in [0, num_rows).
            Shape (N,).
        num_rows (int): M.

    Returns:
        Tensor: Means; rows that receive nothing are 0. Shape (M, C).
    """
    total = src.new_zeros(num_rows, src.shape[1]).index_add(0, index, src)
    if accelerator_path(index):
        # bincount reads the largest index on the host (a sync on GPUs);
        # an index_add of ones gives the same counts without one.
        counts = torch.zeros(num_rows, dtype=torch.long,
                             device=index.device).index_add_(
                                 0, index, torch.ones_like(index))
    else:
        counts = torch.bincount(index, minlength=num_rows)
    return total / counts.clamp(min=1).to(src.dtype)[:, None]


def point_voxel_offsets(xyz: Tensor, rows: Tensor, num_voxels: int,
                        voxel_zyx: Tensor, voxel_size: Sequence[float],
                        range_min: Sequence[float]) -> Tensor:
    """Offset of every point to the mean of its voxel and to its centre.

    The normalised point features of SPVCNN-style LiDAR branches (and of
    PointPillars' voxel feature encoder): ``p - mean_{q in v(p)} q`` and
    ``p - c(v(p))`` with the voxel centre ``c(v) = range_min + (v + 0.5) *
    voxel_size``, in metres.

    Args:
        xyz (Tensor): Point coordinates (x, y, z), metres. Shape (P, 3).
        rows (Tensor): Voxel of each point, in [0, num_voxels). Shape (P,).
        num_voxels (int): Number of voxels.
        voxel_zyx (Tensor): Integer voxel index of each point, ordered
            (z, y, x). Shape (P, 3).
        voxel_size (Sequence[float]): (x, y, z) voxel edge, metres.
        range_min (Sequence[float]): (x, y, z) of the grid's corner.

    Returns:
        Tensor: ``(dx, dy, dz)`` to the mean, then to the centre.
        Shape (P, 6).
    """
    mean = scatter_mean(xyz, rows, num_voxels)[rows]
    size = xyz.new_tensor(voxel_size)
    centre = xyz.new_tensor(range_min) + (voxel_zyx.flip(1).to(xyz.dtype) +
                                          0.5) * size
    return torch.cat([xyz - mean, xyz - centre], dim=1)


def coord_index(x: SparseTensor) -> CoordIndex:
    """Lookup structure over the sites of a sparse tensor.

    Args:
        x (SparseTensor): Sites of shape (N, 4).

    Returns:
        CoordIndex: Maps linearised ``(batch, z, y, x)`` keys to rows.
    """
    return CoordIndex(
        linearize(x.coords[:, 0], x.coords[:, 1:], x.spatial_shape))


def voxel_rows(x: SparseTensor,
               batch: Tensor,
               zyx: Tensor,
               index: Optional[CoordIndex] = None) -> Tensor:
    """Row of ``x`` holding each point's voxel.

    Args:
        x (SparseTensor): Voxels on a (Z, Y, X) grid.
        batch (Tensor): Sample of each point. Shape (P,).
        zyx (Tensor): Integer voxel of each point on ``x``'s grid.
            Shape (P, 3).
        index (CoordIndex, optional): Prebuilt :func:`coord_index` of
            ``x``. Defaults to None (built here).

    Returns:
        Tensor: int64 rows, -1 where the voxel is not active. Shape (P,).
    """
    index = coord_index(x) if index is None else index
    inside = in_bounds(zyx, x.spatial_shape)
    upper = torch.tensor(x.spatial_shape, device=zyx.device) - 1
    keys = linearize(batch, torch.minimum(zyx.clamp(min=0), upper),
                     x.spatial_shape)
    rows = index.query(keys)
    return torch.where(inside, rows, torch.full_like(rows, -1))


def point_to_voxel(x: SparseTensor, point_features: Tensor,
                   rows: Tensor) -> Tensor:
    """Average point features into the voxels of ``x``.

    Args:
        x (SparseTensor): Target voxels (N sites).
        point_features (Tensor): Shape (P, C).
        rows (Tensor): Voxel row of each point, all valid (>= 0), e.g. from
            :func:`voxel_rows`. Shape (P,).

    Returns:
        Tensor: Per-voxel mean; voxels without points get 0. Shape (N, C).
    """
    return scatter_mean(point_features, rows, x.num_voxels)


class TrilinearPlan(NamedTuple):
    """The eight voxels each point blends, with their weights.

    They depend only on the point positions and the voxel sites of one
    grid, not on the features, so one plan serves every feature map on
    that grid (and its backward pass).

    Attributes:
        rows (Tensor): int64 row of each corner voxel, 0 where the corner
            is inactive or off the grid (its weight is 0). Shape (P, 8).
        weights (Tensor): Trilinear weights renormalised over the active
            corners; all 0 for a point with none. Shape (P, 8).
    """
    rows: Tensor
    weights: Tensor


def trilinear_plan(x: SparseTensor,
                   batch: Tensor,
                   position: Tensor,
                   index: Optional[CoordIndex] = None) -> TrilinearPlan:
    """Corner voxels and weights of :func:`trilinear_devoxelize`.

    A point at ``u`` (grid units, ``(z, y, x)``) blends the voxels
    ``base + c``, ``c`` in {0, 1}^3 (corner ``4 c_z + 2 c_y + c_x``), with
    ``base = floor(u - 0.5)``. The corners depend only on the point's
    ``(batch, base)`` cell, which many points share (a 0.1 m voxel of a
    10-sweep cloud holds tens of points, and a coarser stage's cell
    more), so the eight lookups run once per run of equal cells: with the
    points grouped by cell, as :class:`SPVCNNEncoder` orders them, that is
    once per cell. Any order gives the same plan, only more lookups.

    Args:
        x (SparseTensor): Voxels on a (Z, Y, X) grid.
        batch (Tensor): Sample of each point. Shape (P,).
        position (Tensor): Point positions in ``x``'s grid units, ordered
            ``(z, y, x)``. Shape (P, 3).
        index (CoordIndex, optional): Prebuilt :func:`coord_index` of
            ``x``. Defaults to None (built here).

    Returns:
        TrilinearPlan: Rows and weights. Shape (P, 8) each.
    """
    num_points = position.shape[0]
    dtype = x.features.dtype
    if num_points == 0 or x.num_voxels == 0:
        return TrilinearPlan(
            torch.zeros(num_points, 8, dtype=torch.long,
                        device=position.device),
            torch.zeros(num_points, 8, dtype=dtype, device=position.device))
    index = coord_index(x) if index is None else index
    shifted = position - 0.5
    base = torch.floor(shifted)
    frac = (shifted - base).to(dtype)
    base = base.long()
    if accelerator_path(position):
        rows, miss = _point_corner_rows(batch.long(), base, x.spatial_shape,
                                        index)
    else:
        rows, miss = _cell_corner_rows(batch.long(), base, x.spatial_shape,
                                       index)
    # The products run corner-major, over contiguous rows of P (a
    # trailing axis of 2 is several times slower on CPU), and are
    # transposed once.
    frac = frac.t().contiguous()
    axes = torch.stack([1.0 - frac, frac], dim=1)  # (3, 2, P)
    weights = (axes[0][:, None, None] * axes[1][None, :, None]) * \
        axes[2][None, None]  # (c_z, c_y, c_x, P)
    weights = weights.reshape(8, -1).t().contiguous().masked_fill_(miss, 0.0)
    weights = weights.div_(weights.sum(dim=1, keepdim=True).clamp_(min=1e-12))
    return TrilinearPlan(rows.masked_fill_(miss, 0), weights)


def _cell_corner_rows(batch: Tensor, base: Tensor,
                      spatial_shape: Sequence[int],
                      index: CoordIndex) -> Tuple[Tensor, Tensor]:
    """Corner rows looked up once per run of equal cells (the CPU's path).

    One key per (batch, base) cell on the grid grown by one cell below
    (base is -1 left of the first centre); equal neighbours share their
    lookups, which with the points grouped by cell saves most of the
    searches. A point farther out (never one inside the grid) has no corner
    on the grid; clamping only keeps its key unique. ``unique_consecutive``
    reads its result's size on the host: a sync on GPUs, which take
    :func:`_point_corner_rows`.

    Args:
        batch (Tensor): int64 sample of each point. Shape (P,).
        base (Tensor): int64 ``floor(u - 0.5)``, ``(z, y, x)``.
            Shape (P, 3).
        spatial_shape (Sequence[int]): The voxel grid (Z, Y, X).
        index (CoordIndex): Lookup of the voxels.

    Returns:
        tuple[Tensor, Tensor]: int64 rows (-1 where missing) and the bool
        mask of missing corners. Shape (P, 8) each.
    """
    upper = base.new_tensor(spatial_shape)
    off_grid = ((base < -1) | (base >= upper)).any(dim=1)
    grown = tuple(n + 1 for n in spatial_shape)
    cell = linearize(batch, torch.minimum((base + 1).clamp(min=0), upper),
                     grown)
    cells, inverse = torch.unique_consecutive(cell, return_inverse=True)
    rows = _corner_rows(delinearize(cells, grown).long(), spatial_shape,
                        index).index_select(0, inverse)
    return rows, (rows < 0) | off_grid[:, None]


def _point_corner_rows(batch: Tensor, base: Tensor,
                       spatial_shape: Sequence[int],
                       index: CoordIndex) -> Tuple[Tensor, Tensor]:
    """Corner rows of every point in one search (the GPUs' path).

    All 8 P corners at once: a fixed dozen operations and no host sync,
    where :func:`_cell_corner_rows` takes a ``unique_consecutive`` and
    ~100 small operations. Same arguments and result.
    """
    corners = base.unsqueeze(1) + base.new_tensor(_CORNERS)  # (P, 8, 3)
    inside = ((corners >= 0) &
              (corners < base.new_tensor(spatial_shape))).all(dim=2)
    # Keys of corners off the grid may alias other voxels: masked by
    # ``inside``.
    keys = linearize(
        batch.unsqueeze(1).expand(-1, 8).reshape(-1), corners.view(-1, 3),
        spatial_shape)
    rows = index.query(keys).view(-1, 8)
    return rows, (rows < 0) | ~inside


def _corner_rows(cells: Tensor, spatial_shape: Sequence[int],
                 index: CoordIndex) -> Tensor:
    """Rows of the eight corners of cells ``(batch, base + 1)``.

    Args:
        cells (Tensor): Cells on the grid grown by one, as
            :func:`delinearize` gives them. Shape (U, 4).
        spatial_shape (Sequence[int]): The voxel grid (Z, Y, X).
        index (CoordIndex): Lookup of the voxels.

    Returns:
        Tensor: int64 rows, -1 where the corner is inactive or off the
        grid, corner ``4 c_z + 2 c_y + c_x``. Shape (U, 8).
    """
    size_z, size_y, size_x = spatial_shape
    batch, base = cells[:, 0], cells[:, 1:] - 1
    x_ok = [(base[:, 2] + c >= 0) & (base[:, 2] + c < size_x) for c in (0, 1)]
    rows = []
    for c_z, c_y in itertools.product((0, 1), repeat=2):
        corner_z, corner_y = base[:, 0] + c_z, base[:, 1] + c_y
        zy_ok = (corner_z >= 0) & (corner_z < size_z) & (corner_y >= 0) & \
            (corner_y < size_y)
        # The two x-neighbours have consecutive keys: one search for both.
        # Keys of out-of-grid corners may alias other voxels; masked below.
        start = ((batch * size_z + corner_z) * size_y + corner_y) * size_x \
            + base[:, 2]
        for c_x, found in enumerate(index.query_run(start, 2)):
            ok = zy_ok & x_ok[c_x]
            rows.append(torch.where(ok, found, torch.full_like(found, -1)))
    return torch.stack(rows, dim=1)


def devoxelize(features: Tensor, plan: TrilinearPlan) -> Tensor:
    """Blend voxel features at the points of a :class:`TrilinearPlan`.

    Args:
        features (Tensor): Features of the plan's voxels. Shape (N, C).
        plan (TrilinearPlan): From :func:`trilinear_plan` on their grid.

    Returns:
        Tensor: Shape (P, C).
    """
    if plan.rows.shape[0] == 0 or features.shape[0] == 0:
        return features.new_zeros(plan.rows.shape[0], features.shape[1])
    # embedding_bag sums weighted rows without materialising (P, 8, C),
    # which at 300k points and 128 channels would be over 1 GB.
    return F.embedding_bag(
        plan.rows, features, per_sample_weights=plan.weights, mode='sum')


def trilinear_devoxelize(x: SparseTensor,
                         batch: Tensor,
                         position: Tensor,
                         index: Optional[CoordIndex] = None) -> Tensor:
    """Interpolate voxel features at continuous point positions.

    Voxel ``v`` has its centre at ``v + 0.5`` in grid units. A point at
    ``u`` blends the eight voxels around it with trilinear weights
    ``prod_d (1 - |u_d - 0.5 - v_d|)``; inactive voxels drop out and the
    remaining weights are renormalised to sum to 1, so a point near the
    surface is not pulled towards zero. The point's own voxel is one of the
    eight and has weight >= 1/8, so the sum never vanishes when it is
    active. :func:`trilinear_plan`, then :func:`devoxelize`.

    Args:
        x (SparseTensor): Voxel features of shape (N, C).
        batch, position, index: The points and the optional lookup, as
            for :func:`trilinear_plan`.

    Returns:
        Tensor: Interpolated features; 0 for a point with no active
        neighbour. Shape (P, C).
    """
    return devoxelize(x.features, trilinear_plan(x, batch, position, index))
