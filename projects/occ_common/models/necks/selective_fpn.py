"""mmdet's FPN that builds and computes only the outputs a model reads."""
from typing import Sequence, Tuple

import torch.nn.functional as F
from mmdet3d.registry import MODELS
from mmdet.models.necks import FPN
from torch import Tensor, nn


@MODELS.register_module()
class SelectiveFPN(FPN):
    """``mmdet.FPN`` without the output convolutions nobody reads.

    SDG-OCC aggregates the 1/16 and 1/32 ResNet stages with an FPN and keeps
    the 1/16 map only (Sec. 3.3). ``mmdet.FPN`` also builds and runs the
    3x3 output convolution of the 1/32 level: its parameters never get a
    gradient, which DDP refuses (``find_unused_parameters=False``) and which
    wastes a convolution per image. Here every lateral convolution and the
    top-down path are mmdet's (each kept output needs every coarser level),
    but only the levels in ``out_indices`` get an output convolution.

    ``fpn_convs[j]`` is the convolution of level ``out_indices[j]``, so with
    ``out_indices=(0, )`` the state dict is mmdet's FPN without
    ``fpn_convs.1``.

    Args:
        in_channels (Sequence[int]): Channels of each input level, finest
            first.
        out_channels (int): Channels of every output.
        out_indices (Sequence[int]): Levels returned, among
            0 .. len(in_channels) - start_level - 1, increasing. The finest
            must be 0 (use ``start_level`` to drop finer inputs): a lateral
            convolution below it would be unused. Defaults to (0, ).
        **kwargs: ``mmdet.FPN`` arguments but ``num_outs`` and
            ``add_extra_convs`` (no extra levels: every output is one of the
            inputs' levels).

    Raises:
        ValueError: For ``num_outs``, ``add_extra_convs``, ``end_level`` or
            ``out_indices`` outside the levels, not increasing or not
            starting at 0.
    """

    def __init__(self,
                 in_channels: Sequence[int],
                 out_channels: int,
                 out_indices: Sequence[int] = (0, ),
                 **kwargs) -> None:
        for key in ('num_outs', 'add_extra_convs', 'end_level'):
            if key in kwargs:
                raise ValueError(
                    f'SelectiveFPN sets {key} itself (one output per input '
                    'level, no extra levels); choose the outputs with '
                    'out_indices')
        levels = len(in_channels) - kwargs.get('start_level', 0)
        out_indices = tuple(int(i) for i in out_indices)
        if (not out_indices or out_indices[0] != 0
                or any(b <= a for a, b in zip(out_indices, out_indices[1:]))
                or out_indices[-1] >= levels):
            raise ValueError(
                f'SelectiveFPN out_indices must increase from 0 and stay '
                f'below the {levels} input levels, got {out_indices}')
        super().__init__(list(in_channels), out_channels, num_outs=levels,
                         **kwargs)
        self.out_indices = out_indices
        self.fpn_convs = nn.ModuleList(self.fpn_convs[i] for i in out_indices)

    def forward(self, inputs: Sequence[Tensor]) -> Tuple[Tensor, ...]:
        """Top-down pathway and the selected outputs.

        Args:
            inputs (Sequence[Tensor]): One map per entry of ``in_channels``,
                each Shape (B, C_i, H_i, W_i).

        Returns:
            tuple[Tensor]: One map per ``out_indices`` entry, Shape
            (B, out_channels, H_l, W_l) of input level
            ``start_level + l``.
        """
        if len(inputs) != len(self.in_channels):
            raise ValueError(f'SelectiveFPN expects {len(self.in_channels)} '
                             f'input levels, got {len(inputs)}')
        laterals = [
            conv(inputs[i + self.start_level])
            for i, conv in enumerate(self.lateral_convs)
        ]
        # mmdet's top-down pass (nearest up-sampling to the finer size or
        # by upsample_cfg's scale factor), down to level 0.
        for i in range(len(laterals) - 1, 0, -1):
            if 'scale_factor' in self.upsample_cfg:
                upsampled = F.interpolate(laterals[i], **self.upsample_cfg)
            else:
                upsampled = F.interpolate(
                    laterals[i],
                    size=laterals[i - 1].shape[2:],
                    **self.upsample_cfg)
            laterals[i - 1] = laterals[i - 1] + upsampled
        return tuple(
            conv(laterals[i])
            for conv, i in zip(self.fpn_convs, self.out_indices))
