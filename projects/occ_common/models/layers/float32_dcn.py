"""mmcv's modulated deformable convolution (DCNv2) in a float32 island.

mmcv 2.1's DCNv2 kernels have no bfloat16 (CPU and CUDA alike: the CPU
one raises ``NotImplementedError: "modulated_deformable_im2col_cpu" not
implemented for 'BFloat16'``), so a ResNet with DCN stopped training under
``--amp`` with ``optim_wrapper.dtype=bfloat16``. Under autocast this layer
casts its input up and runs in float32 with autocast off
(:func:`~projects.occ_common.utils.precision.float32_math`); its output
stays float32 and the next layer casts it down where autocast wants.
Without autocast it is mmcv's layer, weights and state dict unchanged.
"""
from mmcv.ops import ModulatedDeformConv2dPack
from mmdet3d.registry import MODELS

from ...utils.precision import float32_math


@MODELS.register_module()
class Float32DCNv2(ModulatedDeformConv2dPack):
    """``ModulatedDeformConv2dPack`` (mmcv's ``'DCNv2'``) computed in
    float32 under autocast; the arguments are mmcv's. Shapes: input (B,
    C_in, H, W), output (B, C_out, H', W')."""

    forward = float32_math(ModulatedDeformConv2dPack.forward)
