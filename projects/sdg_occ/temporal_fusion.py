"""Temporal camera-BEV fusion of SDG-OCC's T-frame input (Sec. 3.1).

SDG-OCC takes "a T-frame consequent sequence of images" (Sec. 3.1, Fig. 3)
but does not say how the frames are combined; its Table 3 baseline is
FlashOcc's BEVDet4D-style model, so we follow BEVDet4D: every frame's
camera BEV is computed in its own ego frame, the previous ones are warped
into the current frame (:func:`warp_bev`), concatenated after the current
one and reduced back to C channels by a small conv.

Frame layout of a T-frame sample (written by ``LoadPreviousKeyFrames``):
``imgs`` (B, T * N, 3, H, W) holds the current frame's N views first, then
frame t-1, t-2, ...; the metainfo holds, for the T-1 previous frames,
``prev_tokens``, ``prev2curr`` (T-1, 4, 4), ``prev_cam2img``,
``prev_lidar2cam``, ``prev_img_aug_matrix``, ``prev_lidar2img``
(T-1, N, 4, 4) and, for the SDG lift, ``prev_points`` (T-1 arrays (P, C)).
"""
from collections import OrderedDict
from typing import List, Optional, Sequence

import numpy as np
import torch
from mmdet3d.structures import Det3DDataSample
from torch import Tensor, nn

from projects.occ_common.geometry.bev_warp import warp_bev

#: Metainfo keys of frame t-k, k >= 1, at index k - 1, and the key each
#: becomes in that frame's own data sample.
PREV_CAMERA_KEYS = dict(
    prev_cam2img='cam2img',
    prev_lidar2cam='lidar2cam',
    prev_img_aug_matrix='img_aug_matrix',
    prev_lidar2img='lidar2img')


class TemporalBEVFusion(nn.Module):
    """Concatenate T aligned BEVs and reduce them to C channels.

    Args:
        channels (int): C, the camera BEV width.
        num_frames (int): T >= 2.
    """

    def __init__(self, channels: int, num_frames: int):
        super().__init__()
        if num_frames < 2:
            raise ValueError('TemporalBEVFusion needs num_frames >= 2, got '
                             f'{num_frames}')
        self.num_frames = int(num_frames)
        # One 3x3 conv-BN-ReLU, BEVDet4D's reduction before its BEV encoder:
        # the smallest layer that can both mix the frames and tolerate the
        # sub-cell misalignment a moving object leaves after warping.
        self.reduce = nn.Sequential(
            nn.Conv2d(channels * num_frames, channels, 3, padding=1,
                      bias=False), nn.BatchNorm2d(channels),
            nn.ReLU(inplace=True))

    def forward(self, current: Tensor, previous: Sequence[Tensor],
                prev2curr: Tensor, point_cloud_range: Sequence[float]
                ) -> Tensor:
        """Fuse the current BEV with the warped previous ones.

        Args:
            current (Tensor): Shape (B, C, Y, X).
            previous (Sequence[Tensor]): T - 1 BEVs of frames t-1, t-2, ...
                in their own frames, each Shape (B, C, Y, X).
            prev2curr (Tensor): Shape (B, T - 1, 4, 4).
            point_cloud_range (Sequence[float]): The BEV grid's range.

        Returns:
            Tensor: Shape (B, C, Y, X).
        """
        if len(previous) != self.num_frames - 1:
            raise ValueError(f'TemporalBEVFusion(num_frames='
                             f'{self.num_frames}) got {len(previous)} '
                             'previous BEVs')
        warped = [
            warp_bev(bev, prev2curr[:, k], point_cloud_range)
            for k, bev in enumerate(previous)
        ]
        return self.reduce(torch.cat([current] + warped, dim=1))


def frame_samples(samples: Sequence[Det3DDataSample],
                  k: int) -> List[Det3DDataSample]:
    """Data samples of frame t-k carrying only its camera metainfo.

    Args:
        samples (Sequence[Det3DDataSample]): The batch of the current frame.
        k (int): 1 for the previous frame, 2 for the one before, ...

    Returns:
        list[Det3DDataSample]: One per sample, with ``cam2img``,
        ``lidar2cam``, ``img_aug_matrix``, ``lidar2img`` (N, 4, 4),
        ``img_shape`` and ``sample_idx`` of frame t-k.
    """
    out = []
    for i, sample in enumerate(samples):
        meta = sample.metainfo
        name = meta.get('sample_idx', i)
        missing = [key for key in PREV_CAMERA_KEYS if key not in meta]
        if missing:
            raise ValueError(f'SDGOcc(num_frames > 1): data sample {name} '
                             f'lacks {missing}; add LoadPreviousKeyFrames to '
                             'the pipeline and pack its keys')
        frame = {}
        for key, own in PREV_CAMERA_KEYS.items():
            values = np.asarray(meta[key])
            if values.shape[0] < k:
                raise ValueError(f'data sample {name}: {key} holds '
                                 f'{values.shape[0]} previous frames, '
                                 f'frame t-{k} was asked for')
            frame[own] = values[k - 1]
        frame['img_shape'] = meta.get('img_shape')
        frame['sample_idx'] = f'{name}@t-{k}'
        out.append(Det3DDataSample(metainfo=frame))
    return out


def frame_points(samples: Sequence[Det3DDataSample], k: int,
                 device: torch.device) -> List[Tensor]:
    """The key-frame points of frame t-k, in its own working frame."""
    points = []
    for i, sample in enumerate(samples):
        prev = sample.metainfo.get('prev_points')
        if prev is None or len(prev) < k:
            raise ValueError(
                f'data sample {sample.metainfo.get("sample_idx", i)} has no '
                f'prev_points for frame t-{k}: the SDG lift of a previous '
                'frame needs its LiDAR points (LoadPreviousKeyFrames('
                'load_points=True))')
        points.append(torch.as_tensor(np.asarray(prev[k - 1]),
                                      dtype=torch.float32, device=device))
    return points


class FrameBEVCache:
    """Test-time cache of per-frame camera BEVs, keyed by sample token.

    On a sequential loader frame t's BEV is the previous BEV of frame t+1,
    so it is computed once (FlashOcc / BEVDet's "sequential" mode). Only
    the last ``capacity`` entries are kept.

    Args:
        capacity (int): Entries kept. Defaults to 8.
    """

    def __init__(self, capacity: int = 8):
        self.capacity = int(capacity)
        self._store = OrderedDict()
        self.hits = 0
        self.misses = 0

    def get(self, tokens: Sequence) -> Optional[Tensor]:
        """The stacked BEVs (B, C, Y, X) of ``tokens``, or None unless all
        are cached."""
        if any(t is None or t not in self._store for t in tokens):
            self.misses += 1
            return None
        self.hits += 1
        return torch.stack([self._store[t] for t in tokens])

    def put(self, tokens: Sequence, bev: Tensor) -> None:
        """Store each sample's BEV (C, Y, X) under its token."""
        for token, one in zip(tokens, bev):
            if token is None:
                continue
            self._store[token] = one.detach()
            self._store.move_to_end(token)
        while len(self._store) > self.capacity:
            self._store.popitem(last=False)

    def clear(self) -> None:
        """Forget every entry (weights changed, or a new run)."""
        self._store.clear()
