"""mmcv's modulated deformable convolution exported as ONNX ``DeformConv``.

mmcv's ``ModulatedDeformConv2d`` (``'DCNv2'``, OccCylindrical's ResNet
stages 3-4) writes itself into a graph as its own custom operator, which
onnxruntime does not run without mmcv's operator library. ONNX has a
standard ``DeformConv`` since opset 19 (onnxruntime runs it on the CPU
from 1.20; 1.32 here), with the same layout: the offsets
``(N, 2 * G * kH * kW, oH, oW)`` as ``(dy, dx)`` pairs per kernel tap and
offset group, the mask ``(N, G * kH * kW, oH, oW)`` applied after the
bilinear sampling. :func:`exportable_deform_convs` makes a module's DCN
layers trace as that operator while computing exactly mmcv's output, so
nothing about the model changes for the export.
"""
import contextlib
import types
from typing import Iterator, List

import torch
from torch import Tensor, nn

#: First opset with ``DeformConv``.
DEFORM_CONV_OPSET = 19


def _pair(value) -> List[int]:
    return [int(v) for v in value] if isinstance(value, (tuple, list)) \
        else [int(value)] * 2


class _ModulatedDeformConv(torch.autograd.Function):
    """mmcv's modulated deformable convolution that traces as ONNX's
    ``DeformConv``."""

    @staticmethod
    def forward(ctx, x: Tensor, weight: Tensor, offset: Tensor, bias: Tensor,
                mask: Tensor, stride, padding, dilation, groups: int,
                deform_groups: int) -> Tensor:
        from mmcv.ops import modulated_deform_conv2d
        return modulated_deform_conv2d(x, offset, mask, weight, bias, stride,
                                       padding, dilation, groups,
                                       deform_groups)

    @staticmethod
    def symbolic(g, x, weight, offset, bias, mask, stride, padding, dilation,
                 groups, deform_groups):
        pads = _pair(padding)
        return g.op(
            'DeformConv', x, weight, offset, bias, mask,
            strides_i=_pair(stride), pads_i=pads + pads,
            dilations_i=_pair(dilation), group_i=int(groups),
            offset_group_i=int(deform_groups))


def modulated_deform_conv(layer: nn.Module, x: Tensor, offset: Tensor,
                          mask: Tensor) -> Tensor:
    """``layer``'s modulated deformable convolution of ``x`` (mmcv's
    values; ONNX ``DeformConv`` in a traced graph).

    Args:
        layer (ModulatedDeformConv2d): mmcv's layer (its weight, bias,
            stride, padding, dilation, groups and offset groups).
        x (Tensor): Shape (N, C_in, H, W).
        offset (Tensor): Shape (N, 2 * G * kH * kW, oH, oW).
        mask (Tensor): Shape (N, G * kH * kW, oH, oW).

    Returns:
        Tensor: Shape (N, C_out, oH, oW).
    """
    bias = layer.bias if layer.bias is not None else \
        layer.weight.new_zeros(layer.weight.shape[0])
    return _ModulatedDeformConv.apply(x, layer.weight, offset, bias, mask,
                                      layer.stride, layer.padding,
                                      layer.dilation, layer.groups,
                                      layer.deform_groups)


def _pack_forward(self, x: Tensor) -> Tensor:
    """``ModulatedDeformConv2dPack.forward`` on :func:`modulated_deform_conv`
    (the offsets and mask from its own ``conv_offset``, as mmcv's)."""
    o1, o2, mask = torch.chunk(self.conv_offset(x), 3, dim=1)
    return modulated_deform_conv(self, x, torch.cat((o1, o2), dim=1),
                                 torch.sigmoid(mask))


def _plain_forward(self, x: Tensor, offset: Tensor, mask: Tensor) -> Tensor:
    """``ModulatedDeformConv2d.forward`` on :func:`modulated_deform_conv`."""
    return modulated_deform_conv(self, x, offset, mask)


def deformable_convs(module: nn.Module) -> List[str]:
    """Names of mmcv's deformable convolutions in ``module``."""
    from mmcv.ops import DeformConv2d, ModulatedDeformConv2d
    return [
        name for name, child in module.named_modules()
        if isinstance(child, (DeformConv2d, ModulatedDeformConv2d))
    ]


@contextlib.contextmanager
def exportable_deform_convs(module: nn.Module) -> Iterator[int]:
    """Within the block, ``module``'s modulated deformable convolutions
    trace as ONNX ``DeformConv`` (their values unchanged); afterwards they
    are mmcv's layers again.

    Yields:
        int: The number of layers switched.

    Raises:
        ValueError: For mmcv's (unmodulated) ``DeformConv2d``, which has no
            such form here, naming the layers.
    """
    from mmcv.ops import (DeformConv2d, ModulatedDeformConv2d,
                          ModulatedDeformConv2dPack)
    plain = [
        name for name, child in module.named_modules()
        if isinstance(child, DeformConv2d)
    ]
    if plain:
        raise ValueError(
            f'{len(plain)} unmodulated deformable convolutions (mmcv '
            f'DeformConv2d), e.g. {plain[:3]}: ONNX export covers mmcv\'s '
            'modulated ones (DCNv2); use dcn=dict(type="DCNv2") or none')
    switched = []
    for child in module.modules():
        if isinstance(child, ModulatedDeformConv2dPack):
            child.forward = types.MethodType(_pack_forward, child)
        elif isinstance(child, ModulatedDeformConv2d):
            child.forward = types.MethodType(_plain_forward, child)
        else:
            continue
        switched.append(child)
    try:
        yield len(switched)
    finally:
        for child in switched:
            del child.forward  # the class's forward again
