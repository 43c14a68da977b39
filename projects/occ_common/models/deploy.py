"""Inference-only rewrites of a trained model (deploy time).

Eval-mode BatchNorm after a convolution is an affine map per channel, so it
can be folded into the convolution's weights and bias: one pass over the
feature map instead of two, the same outputs to float rounding: 3.44 ->
2.46 s per 928 x 1600 image for a folded, channels-last ResNet-50 on CPU
(measured 2026-11-23, cbf3bc4).

Folding is applied to the image backbones only (mmdet's ``ResNet`` and its
subclasses), whose layout is known: every BatchNorm there directly
normalises the output of the convolution registered before it. mmcv's
generic :func:`mmcv.cnn.fuse_conv_bn` pairs a BatchNorm with the previous
*registered* child, which other modules (heads, fusion blocks) do not
promise. Training is refused: a folded BatchNorm no longer normalises with
batch statistics nor learns.
"""
import torch
from mmcv.cnn import fuse_conv_bn
from mmdet.models.backbones import ResNet
from torch import nn


def _count_batch_norms(module: nn.Module) -> int:
    return sum(
        isinstance(m, nn.modules.batchnorm._BatchNorm)
        for m in module.modules())


def fuse_backbone_conv_bn(model: nn.Module,
                          channels_last: bool = False) -> int:
    """Fold every BatchNorm of the model's ResNet backbones into its conv.

    Args:
        model (nn.Module): A model in eval mode; changed in place.
        channels_last (bool): Also store the backbones' 4-D weights
            channels-last (faster one-thread 1x1 convolutions on CPU; inputs
            keep their layout). Defaults to False.

    Returns:
        int: The number of BatchNorm layers folded (0 where the model has
        no ResNet backbone).

    Raises:
        RuntimeError: If the model is in training mode.
    """
    if model.training:
        raise RuntimeError(
            'fuse_backbone_conv_bn is for inference: call model.eval() '
            'first (a folded BatchNorm neither normalises batches nor '
            'learns).')
    folded = 0
    for module in list(model.modules()):
        if not isinstance(module, ResNet):
            continue
        before = _count_batch_norms(module)
        with torch.no_grad():
            fuse_conv_bn(module)
        folded += before - _count_batch_norms(module)
        if channels_last:
            module.to(memory_format=torch.channels_last)
    return folded
