"""SPVCNN-style point-voxel LiDAR encoder with a BEV output.

SDG-OCC's LiDAR branch: SPVCNN (Tang et al., ECCV 2020, "Searching
Efficient 3D Architectures with Sparse Point-Voxel Convolution") encodes
the point cloud with a sparse voxel branch and a point branch of MLPs,
fused after every stage (SPVConv, sec. 3.2 and fig. 3), and the result is
compressed to a bird's-eye-view map that the camera BEV is fused and
distilled with.
"""
import math
from typing import Dict, List, Optional, Sequence, Tuple, Union

import torch
from mmdet3d.registry import MODELS
from mmengine.model import BaseModule
from torch import Tensor, nn

from ...utils.eager_island import eager_island
from ..layers.checkpointing import checkpoint_if_grad
from .backend import check_backend
from .dense import scatter_bev, to_dense_bev
from .point_voxel import (coord_index, devoxelize, point_voxel_offsets,
                          scatter_mean, trilinear_plan, voxel_rows)
from .rulebook import delinearize, linearize
from .sparse_blocks import SparseConvBNReLU, SparseResBlock
from .sparse_norm_act import LinearBNReLU
from .sparse_tensor import SparseTensor

_REDUCTIONS = ('max', 'mean', 'concat')


@MODELS.register_module()
class SPVCNNEncoder(BaseModule):
    """Sparse point-voxel encoder whose output is a BEV map and its mask.

    Pipeline (all on the active voxels only):

    1. Voxelise: points inside ``point_cloud_range`` fall in voxels of
       ``voxel_size``; a voxel's input feature is the mean of its points'
       first ``in_channels`` values. With ``point_offsets`` each point
       first gets its offsets to its voxel's mean and centre
       (:func:`point_voxel_offsets`, the "voxelization and normalization"
       of SDG-OCC Sec. 3.5, as in the authors' code) and a point MLP
       (Linear-BN-ReLU, Linear) to ``base_channels``; the voxel feature is
       the mean of these. (The mean of the offsets to the mean is 0, so
       without a per-point layer before the mean they would carry
       nothing.)
    2. Stem: two 3x3x3 submanifold conv-BN-ReLU; the point branch starts as
       the stem's features interpolated at every point.
    3. Stages: a kernel = stride sparse conv down-samples (when the stride
       is > 1), then residual submanifold blocks. After each stage the
       point-voxel fusion of SPVConv runs:
       ``z_i = devox(x_i) + MLP_i(z_{i-1})`` (trilinear voxel -> point plus
       the point branch) and ``x_i <- x_i + mean_{p in v} z_i[p]``
       (scatter-mean point -> voxel, added to keep the voxel features of
       the conv branch).
    4. BEV: voxel features go through Linear-BN-ReLU and are max- (or
       mean-) pooled into the BEV cell of their centre, or (``'concat'``)
       the height levels are stacked as channels and mixed by a 1x1 conv.

    The BEV map is ``(B, C, Y, X)``: dim -1 indexes x and dim -2 indexes y,
    with cell ``floor((coord - range_min) / bev_cell)`` and
    ``bev_cell = (range_max - range_min) / bev_shape`` per axis, the
    convention of mmdet3d's BEV maps and of the SDG-OCC camera BEV.

    Args:
        in_channels (int): Point features used, the first columns of each
            point (x, y, z, intensity[, time]). Defaults to 4.
        voxel_size (Sequence[float]): ``(x, y, z)`` voxel edge in metres.
            Defaults to (0.1, 0.1, 0.1), SDG-OCC's.
        point_cloud_range (Sequence[float]): ``(x_min, y_min, z_min, x_max,
            y_max, z_max)``; points outside are dropped. Defaults to
            (-40, -40, -1, 40, 40, 5.4), Occ3D-nuScenes'.
        base_channels (int): Stem channels. Defaults to 32, SPVCNN's.
        stage_channels (Sequence[int]): Channels per stage.
            Defaults to (64, 128).
        stage_strides (Sequence[int]): Down-sampling of each stage (1 keeps
            the scale). Defaults to (2, 2): 0.4 m voxels, one per BEV cell
            of a 200x200 grid over 80 m.
        blocks_per_stage (int): Residual blocks per stage. Defaults to 1.
        bev_shape (Sequence[int]): ``(H, W)`` = (y cells, x cells).
            Defaults to (200, 200), Occ3D's.
        out_channels (int): BEV channels. Defaults to 128.
        bev_reduce (str): ``'max'``, ``'mean'`` or ``'concat'``.
            Defaults to ``'max'``.
        point_offsets (bool): Add the per-point offsets to the voxel mean
            and centre and the point MLP (step 1). Defaults to False.
        bev_output (bool): Build the BEV projection (step 4). False builds
            an encoder of point features only (:meth:`encode_points`), as
            the lidarseg pre-training of SDG-OCC's release trains it, whose
            checkpoint then loads into one with the BEV projection (that
            projection's keys allowed missing). Defaults to True.
        backend (str): Sparse conv backend, ``'auto'``, ``'spconv'`` or
            ``'torch'``. Defaults to ``'auto'``.
        with_cp (bool): In training, keep only each segment's inputs
            (the stem's, then each stage's) for the backward and run the
            segment again there (:func:`checkpoint_if_grad`: exact,
            BatchNorm statistics updated once). The per-point activations
            are the largest tensors of an SDG-OCC training step (1.3 of
            the 2.9 GiB kept at 6x256x704 images and 10 sweeps). Defaults
            to False.
        init_cfg (dict, optional): mmengine initialisation config.
            Defaults to None.
    """

    def __init__(self,
                 in_channels: int = 4,
                 voxel_size: Sequence[float] = (0.1, 0.1, 0.1),
                 point_cloud_range: Sequence[float] = (-40.0, -40.0, -1.0,
                                                       40.0, 40.0, 5.4),
                 base_channels: int = 32,
                 stage_channels: Sequence[int] = (64, 128),
                 stage_strides: Sequence[int] = (2, 2),
                 blocks_per_stage: int = 1,
                 bev_shape: Sequence[int] = (200, 200),
                 out_channels: int = 128,
                 bev_reduce: str = 'max',
                 point_offsets: bool = False,
                 bev_output: bool = True,
                 backend: str = 'auto',
                 with_cp: bool = False,
                 init_cfg: Optional[Union[dict, List[dict]]] = None) -> None:
        super().__init__(init_cfg=init_cfg)
        self.with_cp = with_cp
        self._check_config(in_channels, voxel_size, point_cloud_range,
                           stage_channels, stage_strides, blocks_per_stage,
                           bev_shape, bev_reduce)
        check_backend(backend)
        self.in_channels = in_channels
        self.voxel_size = tuple(float(v) for v in voxel_size)
        self.point_cloud_range = tuple(float(v) for v in point_cloud_range)
        self.stage_strides = tuple(int(s) for s in stage_strides)
        self.total_stride = math.prod(self.stage_strides)
        self.bev_shape = tuple(int(s) for s in bev_shape)
        self.bev_reduce = bev_reduce
        self.sparse_shape = self._sparse_shape()
        self.bev_cell = tuple(
            (self.point_cloud_range[a + 3] - self.point_cloud_range[a]) / n
            for a, n in ((0, self.bev_shape[1]), (1, self.bev_shape[0])))
        self._check_bev_resolution()

        self.point_offsets = point_offsets
        stem_in = in_channels
        if point_offsets:
            self.point_input = nn.Sequential(
                LinearBNReLU(in_channels + 6, base_channels),
                nn.Linear(base_channels, base_channels))
            stem_in = base_channels
        self.stem = nn.Sequential(
            SparseConvBNReLU('subm', stem_in, base_channels, kernel_size=3,
                             indice_key='subm0', backend=backend),
            SparseConvBNReLU('subm', base_channels, base_channels,
                             kernel_size=3, indice_key='subm0',
                             backend=backend))
        self.stages = nn.ModuleList()
        self.point_mlps = nn.ModuleList()
        channels, point_channels, level = base_channels, base_channels, 0
        for stage_out, stride in zip(stage_channels, self.stage_strides):
            layers = []
            if stride > 1:
                level += 1
                # kernel = stride: every output voxel is the parent of the
                # input voxels below it, so each point keeps a voxel.
                layers.append(
                    SparseConvBNReLU('conv', channels, stage_out,
                                     kernel_size=stride, stride=stride,
                                     indice_key=f'down{level}',
                                     backend=backend))
                channels = stage_out
            for _ in range(blocks_per_stage):
                layers.append(
                    SparseResBlock(channels, stage_out,
                                   indice_key=f'subm{level}',
                                   backend=backend))
                channels = stage_out
            self.stages.append(nn.Sequential(*layers))
            self.point_mlps.append(LinearBNReLU(point_channels, stage_out))
            point_channels = stage_out
        self.bev_proj = None
        if bev_output and bev_reduce == 'concat':
            levels = self.sparse_shape[0] // self.total_stride
            self.bev_proj = nn.Sequential(
                nn.Conv2d(channels * levels, out_channels, 1, bias=False),
                nn.BatchNorm2d(out_channels), nn.ReLU(inplace=True))
        elif bev_output:
            self.bev_proj = LinearBNReLU(channels, out_channels)
        self.out_channels = out_channels
        #: Channels of the point features of :meth:`encode_points`.
        self.point_channels = point_channels

    @staticmethod
    def _check_config(in_channels, voxel_size, point_cloud_range,
                      stage_channels, stage_strides, blocks_per_stage,
                      bev_shape, bev_reduce) -> None:
        """Reject inconsistent arguments with a message naming them."""
        if in_channels < 3:
            raise ValueError('SPVCNNEncoder in_channels must be >= 3 (x, y, '
                             f'z first), got {in_channels}')
        if len(voxel_size) != 3 or min(voxel_size) <= 0:
            raise ValueError('SPVCNNEncoder voxel_size must be 3 positive '
                             f'sizes (x, y, z), got {voxel_size}')
        if len(point_cloud_range) != 6 or any(
                point_cloud_range[a + 3] <= point_cloud_range[a]
                for a in range(3)):
            raise ValueError(
                'SPVCNNEncoder point_cloud_range must be (x_min, y_min, '
                f'z_min, x_max, y_max, z_max), got {point_cloud_range}')
        if len(stage_channels) != len(stage_strides) or \
                min(stage_strides, default=1) < 1:
            raise ValueError(
                'SPVCNNEncoder needs one stride >= 1 per stage, got '
                f'stage_channels={stage_channels}, '
                f'stage_strides={stage_strides}')
        if blocks_per_stage < 1:
            raise ValueError('SPVCNNEncoder blocks_per_stage must be >= 1, '
                             f'got {blocks_per_stage}')
        if len(bev_shape) != 2 or min(bev_shape) < 1:
            raise ValueError('SPVCNNEncoder bev_shape must be (H, W), got '
                             f'{bev_shape}')
        if bev_reduce not in _REDUCTIONS:
            raise ValueError(f'SPVCNNEncoder bev_reduce must be one of '
                             f'{_REDUCTIONS}, got {bev_reduce!r}')

    def _sparse_shape(self) -> Tuple[int, int, int]:
        """Sparse voxel grid ``(Z, Y, X)`` (spconv's and mmdet3d's
        ``sparse_shape``), padded to a multiple of the stride.

        Padding lets every down-sampling keep the last partial voxel; the
        padded cells lie outside the range and never hold a point.
        """
        sizes = []
        for axis in (2, 1, 0):
            extent = self.point_cloud_range[axis + 3] - \
                self.point_cloud_range[axis]
            # The tolerance absorbs float error such as 6.4 / 0.1 = 64.0...1.
            cells = math.ceil(extent / self.voxel_size[axis] - 1e-6)
            sizes.append(math.ceil(cells / self.total_stride) *
                         self.total_stride)
        return tuple(sizes)

    def _check_bev_resolution(self) -> None:
        """The last stage's voxels must fit the BEV grid (see bev_reduce)."""
        coarse = [v * self.total_stride for v in self.voxel_size[:2]]
        if self.bev_reduce == 'concat':
            final = (self.sparse_shape[1] // self.total_stride,
                     self.sparse_shape[2] // self.total_stride)
            if final != self.bev_shape:
                raise ValueError(
                    f"SPVCNNEncoder bev_reduce='concat' needs the last "
                    f'stage grid (Y, X)={final} to equal bev_shape='
                    f'{self.bev_shape}; change stage_strides or voxel_size')
        elif any(c > b * (1 + 1e-6) for c, b in zip(coarse, self.bev_cell)):
            raise ValueError(
                f'SPVCNNEncoder last-stage voxels ({coarse[0]:g} x '
                f'{coarse[1]:g} m) are coarser than the BEV cells '
                f'({self.bev_cell[0]:g} x {self.bev_cell[1]:g} m) and would '
                'leave holes; reduce stage_strides or enlarge the cells')

    def _gather_points(self, points: Sequence[Tensor]
                       ) -> Tuple[Tensor, Tensor, Tensor]:
        """Concatenate the samples and drop points outside the range.

        Returns:
            tuple[Tensor]: Batch index (P,), position in voxel units
            ``(z, y, x)`` (P, 3), features (P, in_channels) and the kept
            rows of the concatenated input (P,).
        """
        if not isinstance(points, (list, tuple)) or len(points) == 0:
            raise ValueError('SPVCNNEncoder expects a non-empty list or tuple'
                             ' of per-sample point tensors, got '
                             f'{type(points).__name__} {points!r:.60}')
        for i, sample in enumerate(points):
            if not isinstance(sample, Tensor) or sample.dim() != 2 or \
                    sample.shape[1] < self.in_channels or \
                    not sample.is_floating_point():
                shape = tuple(sample.shape) if isinstance(
                    sample, Tensor) else type(sample).__name__
                raise ValueError(
                    f'SPVCNNEncoder sample {i}: expected a float tensor of '
                    f'shape (N, >= {self.in_channels}), got {shape}')
        cat = torch.cat([p[:, :self.in_channels] for p in points])
        batch = torch.cat([
            torch.full((p.shape[0], ), i, dtype=torch.long, device=p.device)
            for i, p in enumerate(points)
        ])
        low = cat.new_tensor(self.point_cloud_range[:3])
        high = cat.new_tensor(self.point_cloud_range[3:])
        xyz = cat[:, :3]
        # One host read of the kept count (three boolean indexes would
        # read it three times).
        keep = ((xyz >= low) & (xyz < high)).all(dim=1).nonzero().squeeze(1)
        cat = cat.index_select(0, keep)
        position = (cat[:, :3] - low) / cat.new_tensor(self.voxel_size)
        return batch.index_select(0, keep), position.flip(1), cat, keep

    def _bev_cells(self, coords: Tensor, stride: int) -> Tuple[Tensor, Tensor]:
        """BEV (row, column) of the centres of voxels at a given stride."""
        cells = []
        for axis, column in ((1, 2), (0, 3)):  # (y, x)
            centre = (coords[:, column].double() + 0.5) * \
                self.voxel_size[axis] * stride
            limit = self.bev_shape[1 - axis] - 1
            cells.append(torch.floor(centre / self.bev_cell[axis]).long()
                         .clamp(0, limit))
        return cells[0], cells[1]

    def _to_bev(self, x: SparseTensor) -> Tensor:
        """Compress the last stage into the BEV map. Shape (B, C, H, W)."""
        if self.bev_reduce == 'concat':
            bev = self.bev_proj(to_dense_bev(x, 'concat'))
            # The dense 1x1 conv's batch-norm shift would light up empty
            # columns; keep them zero, as the pooled reductions do.
            coords = x.coords.long()
            active = bev.new_zeros(x.batch_size, 1, *bev.shape[2:])
            active[coords[:, 0], 0, coords[:, 2], coords[:, 3]] = 1
            return bev * active
        cell_y, cell_x = self._bev_cells(x.coords, self.total_stride)
        return scatter_bev(
            self.bev_proj(x.features), x.coords[:, 0], cell_y, cell_x,
            x.batch_size, self.bev_shape, self.bev_reduce)

    def _bev_mask(self, coords: Tensor, batch_size: int) -> Tensor:
        """Which BEV cells hold an input voxel. Shape (B, 1, H, W), bool."""
        height, width = self.bev_shape
        cell_y, cell_x = self._bev_cells(coords, 1)
        flat = (coords[:, 0].long() * height + cell_y) * width + cell_x
        mask = torch.zeros(
            batch_size * height * width, dtype=torch.bool,
            device=coords.device)
        mask[flat] = True
        return mask.view(batch_size, 1, height, width)

    # Every layer's size is the data's (voxels, rulebook pairs): under
    # torch.compile the encoder runs eagerly, one graph break, instead of
    # breaking at each of them and compiling again for every point count.
    @eager_island(dynamic_dim=None)
    def forward(self, points: Sequence[Tensor]) -> Dict[str, Tensor]:
        """Encode a batch of point clouds into BEV features.

        Args:
            points (Sequence[Tensor]): One float tensor per sample, columns
                (x, y, z, intensity, ...). Shape (N_i, >= in_channels).
                Samples may be empty.

        Returns:
            dict[str, Tensor]:

            - bev: BEV features, zero where no LiDAR voxel lies.
              Shape (B, out_channels, H, W).
            - bev_mask: True where a cell holds a LiDAR voxel.
              Shape (B, 1, H, W), bool.
            - point_feats, point_index: As :meth:`encode_points`.
        """
        if self.bev_proj is None:
            raise ValueError('SPVCNNEncoder(bev_output=False) has no BEV '
                             'projection: call encode_points')
        out = self.encode_points(points)
        x = out.pop('voxels')
        return dict(
            bev=self._to_bev(x),
            bev_mask=self._bev_mask(out.pop('coords'), len(points)), **out)

    def encode_points(self, points: Sequence[Tensor]) -> Dict:
        """Voxel and point features of a batch, without the BEV (steps
        1-3 of the class doc).

        Args:
            points (Sequence[Tensor]): As :meth:`forward`'s.

        Returns:
            dict:

            - point_feats (Tensor): The point branch after the last stage,
              for the points inside ``point_cloud_range``, grouped by
              voxel. Shape (P, point_channels).
            - point_index (Tensor): Row of each of them in
              ``torch.cat(points)``. Shape (P,), long.
            - voxels (SparseTensor): The last stage's voxels.
            - coords (Tensor): The input voxels (batch, z, y, x).
              Shape (V, 4).
        """
        # Recomputed in segments (the stem, then each stage) so that
        # the backward rebuilds one segment's activations at a time; the
        # per-point features between segments are kept.
        segment, point_index = self._group_points(points)
        batch, position, coords, rows = segment[:4]
        # Made outside the segments: their recomputation reuses the
        # rulebooks of the first run (SparseTensor.rulebook_memo).
        rulebook_memo = {}
        x, point_feats = checkpoint_if_grad(self.with_cp, self._stem, *segment,
                                            rulebook_memo, module=self)
        stride = 1
        for index, stage_stride in enumerate(self.stage_strides):
            stride *= stage_stride
            x, point_feats = checkpoint_if_grad(
                self.with_cp, self._stage, index, stride, x, point_feats,
                batch, position, coords, rows, module=self)
        return dict(point_feats=point_feats, point_index=point_index,
                    voxels=x, coords=coords)

    def _group_points(self, points: Sequence[Tensor]) -> tuple:
        """The points in range, grouped by voxel, and their voxels.

        Args:
            points (Sequence[Tensor]): As :meth:`forward`'s.

        Returns:
            tuple: The segment: ``batch`` (P, ), ``position`` in voxels
            (P, 3), ``coords`` (V, 4) of the occupied voxels, ``rows``
            (P, ) each point's voxel, ``features`` (P, C) and ``fine``
            (P, 3) each point's voxel index, and the batch size; and each
            point's row in the concatenated input (P, ).
        """
        batch, position, features, kept = self._gather_points(points)
        # float32 rounding can put a point just below the range maximum
        # on the boundary cell index; keep it in the last cell.
        upper = position.new_tensor(self.sparse_shape).long() - 1
        fine = torch.minimum(torch.floor(position).long(), upper)
        keys, rows = torch.unique(
            linearize(batch, fine, self.sparse_shape), return_inverse=True)
        # Grouping the points by voxel makes every later voxel lookup of
        # the points nearly sequential (several times faster on CPU), and
        # by the eighth of their voxel within it lets the first
        # trilinear_plan look up the corners once per group; the outputs
        # do not depend on the point order.
        eighth = (torch.floor(position - 0.5).long() - fine + 1).clamp(0, 1)
        order = torch.argsort(rows * 8 + (eighth * eighth.new_tensor(
            [4, 2, 1])).sum(dim=1))
        batch, position, features, fine, rows = (
            t[order] for t in (batch, position, features, fine, rows))
        coords = delinearize(keys, self.sparse_shape)
        return ((batch, position, coords, rows, features, fine, len(points)),
                kept[order])

    def _stem(self, batch: Tensor, position: Tensor, coords: Tensor,
              rows: Tensor, features: Tensor, fine: Tensor,
              batch_size: int,
              rulebook_memo: dict) -> Tuple[SparseTensor, Tensor]:
        """Voxel features and the stem (steps 1 and 2 of the class doc).

        ``rulebook_memo`` is the forward's (:class:`SparseTensor`).

        Returns:
            tuple: The stem's sparse tensor and the point branch's start,
            its features at every point. Shape (P, base_channels).
        """
        if self.point_offsets:
            offsets = point_voxel_offsets(features[:, :3], rows, len(coords),
                                          fine, self.voxel_size,
                                          self.point_cloud_range[:3])
            features = self.point_input(torch.cat([features, offsets], 1))
        x = SparseTensor(
            scatter_mean(features, rows, len(coords)),
            coords,
            self.sparse_shape,
            batch_size,
            check=False,
            rulebook_memo=rulebook_memo)
        x = self.stem(x)
        return x, devoxelize(x.features, trilinear_plan(x, batch, position))

    def _stage(self, index: int, stride: int, x: SparseTensor,
               point_feats: Tensor, batch: Tensor, position: Tensor,
               coords: Tensor, rows: Tensor) -> Tuple[SparseTensor, Tensor]:
        """Stage ``index`` and its point-voxel fusion (step 3).

        Args:
            index (int): Stage.
            stride (int): Its total stride from the input voxels.
            x (SparseTensor): The previous stage's voxels.
            point_feats (Tensor): The point branch. Shape (P, C_prev).
            batch, position, coords, rows: From :meth:`_group_points`.

        Returns:
            tuple: The stage's voxels and point branch (P, C).
        """
        x = self.stages[index](x)
        voxel_index = coord_index(x)
        # Each stage's corners and weights are looked up once; the in-place
        # sum is safe for autograd (embedding_bag's backward does not keep
        # its output).
        point_feats = devoxelize(
            x.features,
            trilinear_plan(x, batch, position / stride, voxel_index)).add_(
                self.point_mlps[index](point_feats))
        # A point's voxel at this stride is its input voxel's parent: one
        # lookup per input voxel, not per point.
        stage_rows = voxel_rows(
            x, coords[:, 0], torch.div(coords[:, 1:], stride,
                                       rounding_mode='floor'),
            voxel_index)[rows]
        x = x.replace_feature(
            x.features + scatter_mean(point_feats, stage_rows, x.num_voxels))
        return x, point_feats
