"""mmdet's shifted-window attention with its shift mask built once per
padded map shape."""
from typing import Dict, Sequence, Tuple

import torch
import torch.nn.functional as F
from mmdet.models.backbones.swin import ShiftWindowMSA
from torch import Tensor

#: What mmdet's mask adds to the logits of key-query pairs that come from
#: different regions of the shifted map.
MASKED_LOGIT = -100.0


class CachedMaskShiftWindowMSA(ShiftWindowMSA):
    """``ShiftWindowMSA`` that keeps its attention mask between calls.

    mmdet rebuilds the shifted-window mask in every forward: a zero map,
    nine region fills, a window partition and four elementwise operations,
    about 24 kernel launches and nine host-to-device scalar copies a block,
    for a mask that depends only on the padded map size. OccCylindrical
    runs 12 shifted blocks of Swin-S on 3 TPV planes (36 masks a
    prediction, again in every recomputation). Here the mask is built the
    same way once per ``(H_pad, W_pad, device)`` and reused; everything
    else is mmdet's computation, in the same order, so outputs are equal
    (tests/occ_common/models/backbones/test_cached_shift_mask.py).
    The weights and their names are mmdet's.
    """

    def shift_mask(self, height: int, width: int,
                   device: torch.device) -> Tensor:
        """The (nW, ws^2, ws^2) additive mask of a padded map: 0 within a
        region of the cyclically shifted map, -100 across regions."""
        cache: Dict[Tuple, Tensor] = self.__dict__.setdefault(
            '_shift_masks', {})
        key = (height, width, str(device))
        if key not in cache:
            size, shift = self.window_size, self.shift_size
            regions = torch.zeros((1, height, width, 1), device=device)
            bounds = (slice(0, -size), slice(-size, -shift),
                      slice(-shift, None))
            for label, (rows, cols) in enumerate(
                    (r, c) for r in bounds for c in bounds):
                regions[:, rows, cols, :] = label
            labels = self.window_partition(regions).view(-1, size * size)
            differs = labels.unsqueeze(1) != labels.unsqueeze(2)
            cache[key] = torch.zeros(differs.shape,
                                     device=device).masked_fill(
                                         differs, MASKED_LOGIT)
        return cache[key]

    def forward(self, query: Tensor, hw_shape: Sequence[int]) -> Tensor:
        """Window attention of ``query`` (B, H * W, C) on an H x W map,
        shifted by ``shift_size``; returns the same shape."""
        batch, length, channels = query.shape
        height, width = hw_shape
        if length != height * width:
            raise ValueError(f'ShiftWindowMSA: {length} tokens for a '
                             f'{height} x {width} map')
        size, shift = self.window_size, self.shift_size
        query = query.view(batch, height, width, channels)
        pad_right = (size - width % size) % size
        pad_bottom = (size - height % size) % size
        query = F.pad(query, (0, 0, 0, pad_right, 0, pad_bottom))
        padded_h, padded_w = query.shape[1], query.shape[2]
        mask = None
        if shift > 0:
            query = torch.roll(query, shifts=(-shift, -shift), dims=(1, 2))
            mask = self.shift_mask(padded_h, padded_w, query.device)
        windows = self.window_partition(query).view(-1, size * size,
                                                    channels)
        attended = self.w_msa(windows, mask=mask).view(-1, size, size,
                                                       channels)
        out = self.window_reverse(attended, padded_h, padded_w)
        if shift > 0:
            out = torch.roll(out, shifts=(shift, shift), dims=(1, 2))
        if pad_right > 0 or pad_bottom > 0:
            out = out[:, :height, :width, :].contiguous()
        return self.drop(out.view(batch, height * width, channels))


def cache_shift_masks(model: torch.nn.Module) -> int:
    """Turn every ``ShiftWindowMSA`` of ``model`` into a
    :class:`CachedMaskShiftWindowMSA` (same weights, same outputs).

    Returns:
        int: The attention modules switched.
    """
    count = 0
    for module in model.modules():
        if type(module) is ShiftWindowMSA:
            module.__class__ = CachedMaskShiftWindowMSA
            count += 1
    return count
