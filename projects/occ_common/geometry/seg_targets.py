"""Feature-resolution targets of the DepthNet's semantic head.

The 2D semantic maps of SDG-OCC come from lidarseg labels projected into
the images, so they are as sparse as the LiDAR depth. Downsampling them to
the 1/16 feature map the way BEVDepth downsamples depth (nearest return of
each patch, see :func:`projects.occ_common.geometry.depth.patch_min_depth`)
keeps the label of the surface the camera sees in each patch;
nearest-neighbour resampling would instead drop most labels. Both detectors
train their DepthNet's optional semantic head on these targets.
"""
from typing import Optional

import torch
from torch import Tensor


def downsample_seg_labels(gt_seg: Tensor,
                          gt_depth: Tensor,
                          downsample: int,
                          ignore_index: int = 255,
                          empty_label: Optional[int] = None) -> Tensor:
    """Label of the nearest labelled LiDAR return of each patch.

    Within each ``downsample`` x ``downsample`` patch, among the pixels
    whose label is not ``ignore_index``, the one with the smallest positive
    depth wins; labelled pixels without a depth count as infinitely far
    (they win only if no labelled pixel has one). Patches without any
    labelled pixel get ``empty_label``, or ``ignore_index`` when it is None.

    Args:
        gt_seg (Tensor): Integer labels, ``ignore_index`` where none.
            Shape (M, H, W).
        gt_depth (Tensor): LiDAR depth, 0 where none. Shape (M, H, W).
        downsample (int): Feature stride; H and W must be multiples of it.
        ignore_index (int): Label without supervision. Defaults to 255.
        empty_label (int, optional): Label of patches that no labelled
            return hits. Defaults to None (``ignore_index``).

    Returns:
        Tensor: Long labels. Shape (M, H / downsample, W / downsample).
    """
    if gt_seg.dim() != 3 or gt_seg.shape != gt_depth.shape:
        raise ValueError('downsample_seg_labels expects gt_seg and gt_depth '
                         f'of one shape (M, H, W), got {tuple(gt_seg.shape)}'
                         f' and {tuple(gt_depth.shape)}')
    num, height, width = gt_seg.shape
    if downsample < 1 or height % downsample or width % downsample:
        raise ValueError(f'downsample_seg_labels: image {height}x{width} is '
                         f'not a multiple of downsample={downsample}')
    feat_h, feat_w = height // downsample, width // downsample
    labelled = gt_seg != ignore_index
    # Rank: depth for labelled returns, a finite "far" value for labelled
    # pixels without depth, +inf for unlabelled pixels.
    far = torch.finfo(torch.float32).max
    rank = torch.where(gt_depth > 0, gt_depth.float(),
                       torch.full_like(gt_depth, far, dtype=torch.float32))
    rank = torch.where(labelled, rank, torch.full_like(rank, float('inf')))

    def patches(x: Tensor) -> Tensor:
        return x.reshape(num, feat_h, downsample, feat_w,
                         downsample).permute(0, 1, 3, 2, 4).reshape(
                             num, feat_h, feat_w, downsample * downsample)

    best_rank, best = patches(rank).min(dim=-1)
    labels = patches(gt_seg.long()).gather(-1, best.unsqueeze(-1))[..., 0]
    empty = ignore_index if empty_label is None else empty_label
    return torch.where(torch.isinf(best_rank),
                       torch.full_like(labels, empty), labels)
