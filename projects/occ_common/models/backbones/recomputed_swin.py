"""mmdet's Swin Transformer with non-reentrant activation recomputation."""
from mmdet3d.registry import MODELS
from mmdet.models.backbones import SwinTransformer
from torch import Tensor

from ..layers.checkpointing import checkpoint_if_grad
from .cached_shift_mask import cache_shift_masks
from .recomputed_blocks import RecomputedBlocks


@MODELS.register_module()
class RecomputedSwinTransformer(RecomputedBlocks, SwinTransformer):
    """``mmdet.SwinTransformer`` whose ``with_cp`` uses non-reentrant
    recomputation.

    The weights, their names and every argument are those of
    ``mmdet.SwinTransformer``, so its configs and checkpoints load
    unchanged. mmdet's blocks call ``torch.utils.checkpoint`` without
    ``use_reentrant``, which torch warns about on every training forward
    (and says it will refuse); they also skip a block whose input needs no
    gradient. Here ``with_cp=True`` keeps only each block's input and
    recomputes the block in the backward through
    :func:`~projects.occ_common.models.layers.checkpointing.checkpoint_if_grad`
    (non-reentrant, random state restored, so the drop-path masks are the
    same), whenever the block or its input needs a gradient.

    Its shifted-window attention builds each shift mask once per map
    shape (:class:`.CachedMaskShiftWindowMSA`) instead of in every block's
    forward and recomputation.

    Args: those of ``mmdet.SwinTransformer`` (``with_cp``: see
    :class:`.RecomputedBlocks`).
    """

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        cache_shift_masks(self)

    def forward(self, x: Tensor) -> list:
        """Patch embedding, then the stages block by block (as
        ``mmdet.SwinTransformer.forward``).

        Args:
            x (Tensor): Input maps. Shape (N, C_in, H, W).

        Returns:
            list[Tensor]: The normalised outputs of the stages in
            ``out_indices``, each of shape (N, C_i, H / s_i, W / s_i).
        """
        x, hw_shape = self.patch_embed(x)
        if self.use_abs_pos_embed:
            x = x + self.absolute_pos_embed
        x = self.drop_after_pos(x)
        outs = []
        for i, stage in enumerate(self.stages):
            for block in stage.blocks:
                x = checkpoint_if_grad(self.with_cp, block, x, hw_shape,
                                       module=block)
            out, out_hw_shape = x, hw_shape
            if stage.downsample:
                x, hw_shape = stage.downsample(x, hw_shape)
            if i in self.out_indices:
                out = getattr(self, f'norm{i}')(out)
                outs.append(
                    out.view(-1, *out_hw_shape,
                             self.num_features[i]).permute(0, 3, 1,
                                                           2).contiguous())
        return outs
