"""The sparse voxel tensor shared by the spconv and pure-PyTorch backends."""
from typing import Dict, Hashable, Optional, Sequence, Tuple

import torch
from torch import Tensor


class SparseTensor:
    """Features on the active sites of a batched 3D voxel grid.

    Coordinates follow spconv's and mmdet3d's voxel order: each row is
    ``(batch, z, y, x)`` and ``spatial_shape`` is ``(Z, Y, X)``, so a tensor
    built here converts to a ``spconv.SparseConvTensor`` without permuting.
    Every coordinate must be unique; the convolutions rely on it.

    The rulebooks of layers that carry an ``indice_key`` live in
    :attr:`indice_dict`, keyed by ``(backend, indice_key)``. Convolutions
    return a tensor with a shallow copy of the dict plus their own entry,
    and :meth:`replace_feature` shares it, so a rulebook built at one scale
    is reused by every later layer that names the same key (as spconv does).

    :attr:`rulebook_memo` holds the torch backend's rulebooks of one forward
    pass by layer and input sites. Every tensor derived from this one shares
    it by reference, so a segment recomputed in the backward (activation
    checkpointing) finds the rulebooks its first run built instead of
    building them again; give a forward's first tensor a memo made outside
    its checkpointed segments.

    Args:
        features (Tensor): Per-voxel features. Shape (N, C).
        coords (Tensor): Integer voxel coordinates ``(batch, z, y, x)``;
            stored as int32. Shape (N, 4).
        spatial_shape (Sequence[int]): Grid size ``(Z, Y, X)``.
        batch_size (int): Number of samples; ``batch < batch_size`` for every
            row.
        indice_dict (dict, optional): Cached rulebooks. Defaults to None,
            an empty dict.
        check (bool): Whether to verify that the coordinates lie inside the
            grid. Costs one min/max pass. Defaults to True.
        rulebook_memo (dict, optional): The forward's rulebooks, shared by
            reference. Defaults to None, an empty dict.
    """

    def __init__(self,
                 features: Tensor,
                 coords: Tensor,
                 spatial_shape: Sequence[int],
                 batch_size: int,
                 indice_dict: Optional[Dict[Tuple[str, Hashable],
                                            object]] = None,
                 check: bool = True,
                 rulebook_memo: Optional[dict] = None) -> None:
        if not isinstance(features, Tensor) or features.dim() != 2:
            raise ValueError('SparseTensor expects features of shape (N, C), '
                             f'got {_describe(features)}')
        if not isinstance(coords, Tensor) or coords.dim() != 2 \
                or coords.shape[1] != 4:
            raise ValueError('SparseTensor expects coords of shape (N, 4) as '
                             f'(batch, z, y, x), got {_describe(coords)}')
        if coords.dtype.is_floating_point or coords.dtype == torch.bool:
            raise ValueError('SparseTensor expects integer coords, got '
                             f'{coords.dtype}')
        if coords.shape[0] != features.shape[0]:
            raise ValueError(f'SparseTensor got {features.shape[0]} feature '
                             f'rows but {coords.shape[0]} coordinate rows')
        spatial_shape = tuple(int(s) for s in spatial_shape)
        if len(spatial_shape) != 3 or min(spatial_shape) < 1:
            raise ValueError('SparseTensor expects spatial_shape (Z, Y, X) '
                             f'of 3 positive sizes, got {spatial_shape}')
        if int(batch_size) < 1:
            raise ValueError(
                f'SparseTensor expects batch_size >= 1, got {batch_size}')
        self.features = features
        self.coords = coords.to(torch.int32)
        self.spatial_shape = spatial_shape
        self.batch_size = int(batch_size)
        self.indice_dict = {} if indice_dict is None else indice_dict
        self.rulebook_memo = {} if rulebook_memo is None else rulebook_memo
        if check and coords.shape[0] > 0:
            self._check_bounds()

    def _check_bounds(self) -> None:
        """Raise if a coordinate lies outside ``(batch_size, *shape)``."""
        lows = self.coords.amin(dim=0).tolist()
        highs = self.coords.amax(dim=0).tolist()
        limits = (self.batch_size, ) + self.spatial_shape
        names = ('batch', 'z', 'y', 'x')
        for name, low, high, limit in zip(names, lows, highs, limits):
            if low < 0 or high >= limit:
                raise ValueError(
                    f'SparseTensor coords column {name} spans [{low}, '
                    f'{high}] but must lie in [0, {limit - 1}] for '
                    f'batch_size={self.batch_size}, '
                    f'spatial_shape={self.spatial_shape}')

    @property
    def num_voxels(self) -> int:
        """int: Number of active sites N."""
        return self.features.shape[0]

    @property
    def num_channels(self) -> int:
        """int: Feature channels C."""
        return self.features.shape[1]

    @property
    def device(self) -> torch.device:
        """torch.device: Device of the features."""
        return self.features.device

    def replace_feature(self, features: Tensor) -> 'SparseTensor':
        """Return a tensor with new features on the same sites.

        Args:
            features (Tensor): New features. Shape (N, C').

        Returns:
            SparseTensor: Same coords, shape, batch size, rulebook cache and
            memo.
        """
        if features.dim() != 2 or features.shape[0] != self.num_voxels:
            raise ValueError(
                f'replace_feature expects features of shape ({self.num_voxels}'
                f', C), got {tuple(features.shape)}')
        return SparseTensor(
            features,
            self.coords,
            self.spatial_shape,
            self.batch_size,
            indice_dict=self.indice_dict,
            check=False,
            rulebook_memo=self.rulebook_memo)

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(num_voxels={self.num_voxels}, '
                f'channels={self.num_channels}, '
                f'spatial_shape={self.spatial_shape}, '
                f'batch_size={self.batch_size})')


def _describe(value: object) -> str:
    """Short description of a wrong argument for error messages."""
    if isinstance(value, Tensor):
        return f'a tensor of shape {tuple(value.shape)}'
    return f'{type(value).__name__}'
