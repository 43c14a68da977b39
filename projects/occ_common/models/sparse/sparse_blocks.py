"""Sparse conv building blocks: conv-BN-ReLU and the residual block."""
from typing import Optional

import torch.nn.functional as F
from torch import nn

from .sparse_conv import SparseConv, SparseInverseConv, SubMConv
from .sparse_norm_act import SparseReLU, batch_norm_rows
from .sparse_tensor import SparseTensor

_CONV_TYPES = {
    'subm': SubMConv,
    'conv': SparseConv,
    'inverse': SparseInverseConv,
}


class SparseConvBNReLU(nn.Module):
    """A sparse convolution followed by batch norm and (optionally) ReLU.

    The convolution has no bias since the batch norm's shift replaces it.
    The norm is a plain ``nn.BatchNorm1d`` on the features (state-dict keys
    ``norm.*``), so SyncBN conversion applies to it.

    Args:
        conv_type (str): ``'subm'`` (:class:`SubMConv`), ``'conv'``
            (:class:`SparseConv`) or ``'inverse'``
            (:class:`SparseInverseConv`).
        in_channels (int): Input channels.
        out_channels (int): Output channels.
        act (bool): Whether to end with ReLU. Defaults to True.
        **conv_kwargs: Remaining arguments of the convolution (kernel_size,
            stride, padding, indice_key, backend, ...).
    """

    def __init__(self,
                 conv_type: str,
                 in_channels: int,
                 out_channels: int,
                 act: bool = True,
                 **conv_kwargs) -> None:
        super().__init__()
        if conv_type not in _CONV_TYPES:
            raise ValueError(f'conv_type must be one of {sorted(_CONV_TYPES)}'
                             f', got {conv_type!r}')
        self.conv = _CONV_TYPES[conv_type](
            in_channels, out_channels, bias=False, **conv_kwargs)
        self.norm = nn.BatchNorm1d(out_channels)
        self.act = act

    def forward(self, x: SparseTensor) -> SparseTensor:
        """Apply conv, norm and activation.

        Args:
            x (SparseTensor): Features of shape (N, C_in).

        Returns:
            SparseTensor: Features of shape (M, C_out).
        """
        x = self.conv(x)
        features = batch_norm_rows(self.norm, x.features)
        return x.replace_feature(F.relu(features) if self.act else features)


class SparseResBlock(nn.Module):
    """Residual block of two 3x3x3 submanifold convs (He et al., 2016),
    as in SPVCNN's and MinkUNet's encoders.

    ``y = ReLU(BN(conv2(ReLU(BN(conv1(x))))) + shortcut(x))``, where the
    shortcut is the identity or, when channels change, a 1x1 submanifold
    conv with batch norm.

    Args:
        in_channels (int): Input channels.
        out_channels (int): Output channels.
        indice_key (str, optional): Rulebook key shared by the block's
            convs (and its neighbours at the same scale). Defaults to None.
        backend (str): Sparse backend. Defaults to ``'auto'``.
    """

    def __init__(self,
                 in_channels: int,
                 out_channels: int,
                 indice_key: Optional[str] = None,
                 backend: str = 'auto') -> None:
        super().__init__()
        common = dict(indice_key=indice_key, backend=backend)
        self.conv1 = SparseConvBNReLU('subm', in_channels, out_channels,
                                      kernel_size=3, **common)
        self.conv2 = SparseConvBNReLU(
            'subm', out_channels, out_channels, act=False, kernel_size=3,
            **common)
        if in_channels == out_channels:
            self.shortcut = None
        else:
            self.shortcut = SparseConvBNReLU(
                'subm', in_channels, out_channels, act=False, kernel_size=1,
                backend=backend)
        self.act = SparseReLU()

    def forward(self, x: SparseTensor) -> SparseTensor:
        """Apply the block.

        Args:
            x (SparseTensor): Features of shape (N, C_in).

        Returns:
            SparseTensor: Same sites. Shape (N, C_out).
        """
        identity = x if self.shortcut is None else self.shortcut(x)
        out = self.conv2(self.conv1(x))
        return self.act(out.replace_feature(out.features +
                                            identity.features))
