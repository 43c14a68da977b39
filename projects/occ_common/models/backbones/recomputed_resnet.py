"""mmdet's ResNet with exact, complete activation recomputation."""
from mmdet3d.registry import MODELS
from mmdet.models.backbones import ResNet
from torch import Tensor

from ..layers.checkpointing import checkpoint_if_grad
from .recomputed_blocks import RecomputedBlocks


@MODELS.register_module()
class RecomputedResNet(RecomputedBlocks, ResNet):
    """``mmdet.ResNet`` whose ``with_cp`` recomputes every trainable block.

    The weights, their names and everything but ``with_cp`` are those of
    ``mmdet.ResNet``, so its configs and pretrained checkpoints load
    unchanged. ``with_cp=True`` keeps only each residual block's input for
    the backward and recomputes the block there
    (:func:`~projects.occ_common.models.layers.checkpointing.checkpoint_if_grad`),
    differing from mmdet's own ``with_cp`` in two ways:

    - the first block after the frozen stages is recomputed too. mmdet
      recomputes a block only when its *input* requires a gradient, which
      the frozen stage's output never does, so that block keeps all its
      activations: at 6 x 928 x 1600 with ``frozen_stages=1`` they are
      ~1.4 GiB (layer2, block 0, at 1/4 of the image).
    - training BatchNorms (``norm_eval=False``) update their running
      statistics once per forward; mmdet's reentrant recomputation
      updates them a second time.

    Args: those of ``mmdet.ResNet`` (``with_cp``: see
    :class:`.RecomputedBlocks`).
    """

    def forward(self, x: Tensor) -> tuple:
        """Stem, then the residual stages block by block.

        Args:
            x (Tensor): Images. Shape (N, 3, H, W).

        Returns:
            tuple[Tensor]: The outputs of the stages in ``out_indices``,
            each of shape (N, C_i, H / s_i, W / s_i).
        """
        if self.deep_stem:
            x = self.stem(x)
        else:
            x = self.relu(self.norm1(self.conv1(x)))
        x = self.maxpool(x)
        outs = []
        for i, layer_name in enumerate(self.res_layers):
            for block in getattr(self, layer_name):
                x = checkpoint_if_grad(self.with_cp, block, x, module=block)
            if i in self.out_indices:
                outs.append(x)
        return tuple(outs)
