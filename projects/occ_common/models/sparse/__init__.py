"""Sparse convolution backends and the SPVCNN encoder.

Layers take ``backend='spconv'|'torch'|'auto'``; ``'auto'`` runs spconv on
CUDA tensors and the pure-PyTorch backend (forward and backward on CPU or
CUDA) otherwise. Weights use spconv's layout, so checkpoints move freely
between backends.
"""
from .backend import (BACKENDS, resolve_backend, spconv_available,
                      spconv_supports_cuda)
from .dense import scatter_bev, to_dense, to_dense_bev
from .point_seg_head import PointSegHead
from .point_voxel import (TrilinearPlan, coord_index, devoxelize,
                          point_to_voxel, point_voxel_offsets, scatter_mean,
                          trilinear_devoxelize, trilinear_plan, voxel_rows)
from .rulebook import (CoordIndex, Rulebook, conv_output_shape, delinearize,
                       linearize, strided_rulebook, submanifold_rulebook)
from .sparse_blocks import SparseConvBNReLU, SparseResBlock
from .sparse_conv import (SparseConv, SparseConvBase, SparseInverseConv,
                          SubMConv)
from .sparse_norm_act import (LinearBNReLU, SparseBatchNorm, SparseReLU,
                              batch_norm_rows)
from .sparse_tensor import SparseTensor
from .spvcnn_encoder import SPVCNNEncoder
from .torch_backend import rulebook_conv

__all__ = [
    'BACKENDS', 'CoordIndex', 'LinearBNReLU', 'PointSegHead', 'Rulebook',
    'SPVCNNEncoder',
    'TrilinearPlan', 'devoxelize', 'trilinear_plan',
    'SparseBatchNorm', 'SparseConv', 'SparseConvBNReLU', 'SparseConvBase',
    'SparseInverseConv', 'SparseReLU', 'SparseResBlock', 'SparseTensor',
    'SubMConv', 'batch_norm_rows', 'conv_output_shape', 'coord_index',
    'delinearize', 'linearize', 'point_to_voxel', 'point_voxel_offsets',
    'resolve_backend', 'rulebook_conv', 'scatter_bev', 'scatter_mean',
    'spconv_available',
    'spconv_supports_cuda', 'strided_rulebook', 'submanifold_rulebook',
    'to_dense', 'to_dense_bev', 'trilinear_devoxelize', 'voxel_rows'
]
