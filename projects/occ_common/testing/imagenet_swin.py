"""ImageNet Swin checkpoints in the official layout, made for tests.

The official files (``swin_{tiny,small}_patch4_window7_224.pth``) hold
``layers.*`` / ``attn.*`` / ``mlp.fc*`` / ``patch_embed.proj`` keys, a
final ``norm``, the classifier ``head`` and the shifted blocks'
``attn_mask`` buffers; mmdet converts them (``swin_converter``) when they
load into its ``SwinTransformer``. These helpers write files of that
layout from an mmdet Swin of the same architecture, so that the checked
loader (:mod:`projects.occ_common.models.pretrained`) can be tested
without a download.
"""
from typing import Callable, Dict, Optional

import torch
from torch import Tensor, nn

#: mmdet key parts -> the official ones.
OFFICIAL_RENAMES = (('stages.', 'layers.'), ('attn.w_msa.', 'attn.'),
                    ('ffn.layers.0.0.', 'mlp.fc1.'), ('ffn.layers.1.',
                                                      'mlp.fc2.'),
                    ('patch_embed.projection', 'patch_embed.proj'))


def official_swin_state(
        swin: nn.Module,
        num_classes: int = 1000,
        value: Optional[Callable[[str, Tensor], Tensor]] = None
) -> Dict[str, Tensor]:
    """The official-layout state dict of an ImageNet classifier whose
    backbone is ``swin`` (an mmdet ``SwinTransformer`` with RGB input and
    4 x 4 patches).

    Args:
        swin (nn.Module): The backbone.
        num_classes (int): Width of the classifier ``head``.
        value (Callable, optional): ``value(key, tensor)`` gives the file's
            tensor for each backbone entry (official key). Defaults to the
            module's own values.

    Returns:
        dict[str, Tensor]: Official keys -> tensors, with ``norm.*`` (the
        final norm), ``head.*`` and one ``attn_mask`` buffer of the first
        shifted block added.
    """
    value = value or (lambda key, tensor: tensor)
    state = {}
    for key, tensor in swin.state_dict().items():
        if key.startswith('norm'):
            continue  # mmdet's per-level output norms
        for old, new in OFFICIAL_RENAMES:
            key = key.replace(old, new)
        state[key] = value(key, tensor)
    width = swin.num_features[-1]
    state['norm.weight'] = torch.ones(width)
    state['norm.bias'] = torch.zeros(width)
    state['head.weight'] = torch.zeros(num_classes, width)
    state['head.bias'] = torch.zeros(num_classes)
    state['layers.0.blocks.1.attn_mask'] = torch.zeros(1)
    return state


def constant_like(fill: float) -> Callable[[str, Tensor], Tensor]:
    """``value`` for :func:`official_swin_state` that writes tiny files: a
    single stored number broadcast to the entry's shape (stride 0), e.g.
    for the 49.6 M values of a Swin-S."""

    def make(key: str, tensor: Tensor) -> Tensor:
        del key
        return torch.full((1, ), fill, dtype=tensor.dtype).expand(
            tensor.shape)

    return make
