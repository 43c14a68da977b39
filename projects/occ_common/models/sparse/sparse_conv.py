"""Sparse 3D convolution layers with a switchable backend.

Each layer owns one ``weight`` of shape ``(C_out, k_z, k_y, k_x, C_in)``
(spconv 2.x's layout) and an optional ``bias`` of shape ``(C_out,)``, so
its state dict has the keys and shapes of the matching spconv module
(``SubMConv3d``, ``SparseConv3d``, ``SparseInverseConv3d``) and loads from
or into it. ``backend`` is resolved at every call from the input's device
(see :func:`.backend.resolve_backend`).
"""
import math
from typing import Optional, Sequence, Tuple, Union

import torch
from torch import nn

from .backend import check_backend, resolve_backend
from .sparse_tensor import SparseTensor
from .spconv_backend import spconv_sparse_conv
from .torch_backend import torch_sparse_conv

IntOrTriple = Union[int, Sequence[int]]


def _triple(value: IntOrTriple, name: str) -> Tuple[int, int, int]:
    """Expand an int to ``(v, v, v)`` and validate a 3-sequence."""
    if isinstance(value, int):
        value = (value, ) * 3
    value = tuple(int(v) for v in value)
    if len(value) != 3:
        raise ValueError(f'{name} must be an int or 3 ints (z, y, x), got '
                         f'{value}')
    return value


class SparseConvBase(nn.Module):
    """Shared parameters and dispatch of the sparse convolution layers.

    Args:
        in_channels (int): Input channels C_in.
        out_channels (int): Output channels C_out.
        kernel_size (int | Sequence[int]): ``(k_z, k_y, k_x)``.
        stride (int | Sequence[int]): Stride per axis. Defaults to 1.
        padding (int | Sequence[int]): Padding per axis. Defaults to 0.
        dilation (int | Sequence[int]): Dilation per axis. Defaults to 1.
        bias (bool): Whether to add a bias. Defaults to True.
        indice_key (str, optional): Rulebook cache key shared with other
            layers at the same scale. Defaults to None.
        backend (str): ``'auto'``, ``'spconv'`` or ``'torch'``.
            Defaults to ``'auto'``.
        subm (bool): Submanifold: outputs are the input sites.
        inverse (bool): Inverse of the strided conv under ``indice_key``.
    """

    # State-dict version 2 marks spconv 2.x's weight layout. mmdet3d patches
    # spconv's loader to permute any weight saved with another version from
    # mmcv's (k_z, k_y, k_x, C_in, C_out), so without it our checkpoints
    # would be scrambled on their way into spconv modules.
    _version = 2

    def __init__(self,
                 in_channels: int,
                 out_channels: int,
                 kernel_size: IntOrTriple,
                 stride: IntOrTriple = 1,
                 padding: IntOrTriple = 0,
                 dilation: IntOrTriple = 1,
                 bias: bool = True,
                 indice_key: Optional[str] = None,
                 backend: str = 'auto',
                 subm: bool = False,
                 inverse: bool = False) -> None:
        super().__init__()
        if in_channels < 1 or out_channels < 1:
            raise ValueError('sparse conv needs positive channels, got '
                             f'in_channels={in_channels}, '
                             f'out_channels={out_channels}')
        self.in_channels = int(in_channels)
        self.out_channels = int(out_channels)
        self.kernel_size = _triple(kernel_size, 'kernel_size')
        self.stride = _triple(stride, 'stride')
        self.padding = _triple(padding, 'padding')
        self.dilation = _triple(dilation, 'dilation')
        if min(self.kernel_size + self.stride + self.dilation) < 1 or \
                min(self.padding) < 0:
            raise ValueError(
                'sparse conv needs kernel_size, stride, dilation >= 1 and '
                f'padding >= 0, got kernel_size={self.kernel_size}, '
                f'stride={self.stride}, padding={self.padding}, '
                f'dilation={self.dilation}')
        self.indice_key = indice_key
        self.backend = check_backend(backend)
        self.subm = subm
        self.inverse = inverse
        self.weight = nn.Parameter(
            torch.empty(self.out_channels, *self.kernel_size,
                        self.in_channels))
        if bias:
            self.bias = nn.Parameter(torch.empty(self.out_channels))
        else:
            self.register_parameter('bias', None)
        self.reset_parameters()

    @property
    def conv1x1(self) -> bool:
        """bool: Kernel volume 1 at stride 1, a per-site linear map."""
        volume = math.prod(self.kernel_size)
        return volume == 1 and (self.subm or math.prod(self.stride) == 1)

    @property
    def geometry(self) -> tuple:
        """tuple: Hashable description of everything but the parameters."""
        return (self.in_channels, self.out_channels, self.kernel_size,
                self.stride, self.padding, self.dilation, self.subm,
                self.inverse, self.indice_key)

    def reset_parameters(self) -> None:
        """Initialise as ``torch.nn.Conv3d`` (and spconv) do.

        Kaiming-uniform with ``a = sqrt(5)`` reduces to
        ``U(-1 / sqrt(fan_in), 1 / sqrt(fan_in))`` with
        ``fan_in = C_in * k_z * k_y * k_x``; the bias uses the same bound.
        """
        bound = 1.0 / math.sqrt(self.in_channels * math.prod(self.kernel_size))
        nn.init.uniform_(self.weight, -bound, bound)
        if self.bias is not None:
            nn.init.uniform_(self.bias, -bound, bound)

    def _load_from_state_dict(self, state_dict, prefix, local_metadata,
                              strict, missing_keys, unexpected_keys,
                              error_msgs) -> None:
        """Also accept mmcv-spconv 1.x weights, (k_z, k_y, k_x, C_in, C_out).

        Such checkpoints carry a state-dict version below 2; their weight is
        permuted when its shape is mmcv's and not already ours.
        """
        key = prefix + 'weight'
        version = local_metadata.get('version')
        weight = state_dict.get(key)
        if (version is None or version < 2) and weight is not None:
            ours = tuple(self.weight.shape)
            mmcv = (*self.kernel_size, self.in_channels, self.out_channels)
            if tuple(weight.shape) == mmcv and mmcv != ours:
                state_dict[key] = weight.permute(4, 0, 1, 2, 3).contiguous()
        super()._load_from_state_dict(state_dict, prefix, local_metadata,
                                      strict, missing_keys, unexpected_keys,
                                      error_msgs)

    def forward(self, x: SparseTensor) -> SparseTensor:
        """Convolve a sparse tensor.

        Args:
            x (SparseTensor): Input; features of shape (N, C_in).

        Returns:
            SparseTensor: Output; features of shape (M, C_out).
        """
        if not isinstance(x, SparseTensor):
            raise TypeError(f'{self.__class__.__name__} expects a '
                            f'SparseTensor, got {type(x).__name__}')
        if x.num_channels != self.in_channels:
            raise ValueError(
                f'{self.__class__.__name__} expects {self.in_channels} input '
                f'channels, got features of shape {tuple(x.features.shape)}')
        if resolve_backend(self.backend, x.features) == 'spconv':
            return spconv_sparse_conv(self, x)
        return torch_sparse_conv(self, x)

    def extra_repr(self) -> str:
        text = (f'{self.in_channels}, {self.out_channels}, '
                f'kernel_size={self.kernel_size}, stride={self.stride}')
        if any(self.padding):
            text += f', padding={self.padding}'
        if self.dilation != (1, 1, 1):
            text += f', dilation={self.dilation}'
        if self.bias is None:
            text += ', bias=False'
        if self.indice_key is not None:
            text += f', indice_key={self.indice_key!r}'
        return text + f', backend={self.backend!r}'


class SubMConv(SparseConvBase):
    """Submanifold sparse conv: outputs only on the input sites.

    Output site ``q`` sums ``W_k^T f_p`` over the active inputs
    ``p = q + (k - kernel_size // 2) * dilation`` (Graham et al., 2018,
    "3D Semantic Segmentation with Submanifold Sparse Convolutional
    Networks", sec. 3). Layers at one scale that share an ``indice_key``
    share one rulebook.

    Args:
        in_channels (int): Input channels.
        out_channels (int): Output channels.
        kernel_size (int | Sequence[int]): Odd ``(k_z, k_y, k_x)``.
            Defaults to 3.
        dilation (int | Sequence[int]): Dilation per axis. Defaults to 1.
        bias (bool): Whether to add a bias. Defaults to True.
        indice_key (str, optional): Rulebook cache key. Defaults to None.
        backend (str): ``'auto'``, ``'spconv'`` or ``'torch'``.
            Defaults to ``'auto'``.
    """

    def __init__(self,
                 in_channels: int,
                 out_channels: int,
                 kernel_size: IntOrTriple = 3,
                 dilation: IntOrTriple = 1,
                 bias: bool = True,
                 indice_key: Optional[str] = None,
                 backend: str = 'auto') -> None:
        super().__init__(
            in_channels,
            out_channels,
            kernel_size,
            dilation=dilation,
            bias=bias,
            indice_key=indice_key,
            backend=backend,
            subm=True)
        if any(k % 2 == 0 for k in self.kernel_size):
            raise ValueError('SubMConv needs an odd kernel_size, got '
                             f'{self.kernel_size}')


class SparseConv(SparseConvBase):
    """Regular sparse conv: an output site is active if its receptive field
    holds an active input; typically strided to down-sample.

    Output site ``q`` sums ``W_k^T f_p`` over active inputs
    ``p = q * stride - padding + k * dilation``, the sparse counterpart of
    ``torch.nn.functional.conv3d``. Give it an ``indice_key`` to let a
    :class:`SparseInverseConv` undo its down-sampling.

    Args:
        in_channels (int): Input channels.
        out_channels (int): Output channels.
        kernel_size (int | Sequence[int]): ``(k_z, k_y, k_x)``.
        stride (int | Sequence[int]): Stride per axis. Defaults to 1.
        padding (int | Sequence[int]): Padding per axis. Defaults to 0.
        dilation (int | Sequence[int]): Dilation per axis. Defaults to 1.
        bias (bool): Whether to add a bias. Defaults to True.
        indice_key (str, optional): Rulebook cache key. Defaults to None.
        backend (str): ``'auto'``, ``'spconv'`` or ``'torch'``.
            Defaults to ``'auto'``.
    """

    def __init__(self,
                 in_channels: int,
                 out_channels: int,
                 kernel_size: IntOrTriple,
                 stride: IntOrTriple = 1,
                 padding: IntOrTriple = 0,
                 dilation: IntOrTriple = 1,
                 bias: bool = True,
                 indice_key: Optional[str] = None,
                 backend: str = 'auto') -> None:
        super().__init__(in_channels, out_channels, kernel_size, stride,
                         padding, dilation, bias, indice_key, backend)


class SparseInverseConv(SparseConvBase):
    """Inverse of a strided :class:`SparseConv`: back to its input sites.

    It reads the rulebook of the conv under ``indice_key`` backwards: each
    pair ``(p, q, k)`` of that conv adds ``W_k^T f_q`` to output ``p``,
    restoring the finer sites exactly (no dilation of the active set).

    Args:
        in_channels (int): Input channels (the coarse features).
        out_channels (int): Output channels.
        kernel_size (int | Sequence[int]): Must equal the paired conv's
            and have volume > 1.
        indice_key (str): Key of the paired strided conv.
        bias (bool): Whether to add a bias. Defaults to True.
        backend (str): ``'auto'``, ``'spconv'`` or ``'torch'``.
            Defaults to ``'auto'``.
    """

    def __init__(self,
                 in_channels: int,
                 out_channels: int,
                 kernel_size: IntOrTriple,
                 indice_key: str,
                 bias: bool = True,
                 backend: str = 'auto') -> None:
        if not indice_key:
            raise ValueError('SparseInverseConv needs the indice_key of the '
                             'strided conv it inverts')
        super().__init__(
            in_channels,
            out_channels,
            kernel_size,
            bias=bias,
            indice_key=indice_key,
            backend=backend,
            inverse=True)
        if self.conv1x1:
            # spconv takes a shortcut for volume-1 kernels that ignores the
            # indice key, which would silently skip the up-sampling.
            raise ValueError('SparseInverseConv needs a kernel volume > 1, '
                             f'got kernel_size={self.kernel_size}')
