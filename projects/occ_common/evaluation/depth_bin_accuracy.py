"""Where a DepthNet lifts the image features, against the LiDAR.

Both models lift every image feature along its ray with the DepthNet's
bin probabilities, so the distribution decides where the features of a
pixel land. :class:`DepthBinAccuracy` accumulates, over the feature pixels
with a LiDAR return (the nearest return of each patch, as the depth loss
takes it), how much of that distribution sits where the surface is:

- ``top1`` / ``within_one_bin``: % of pixels whose most likely bin is the
  one whose lifted point is nearest the LiDAR depth / at most one bin away;
- ``prob_true``: the mean probability on that bin (1 / D for a uniform
  distribution, 1 for a perfect one-hot);
- ``expected_error_m``: the mean over pixels of
  ``sum_k p_k |d_k - d|``, the distance from the surface at which the
  pixel's feature mass is lifted on average (``d_k``: bin k's point);
- ``entropy``: the mean entropy of the distributions in nats (``ln D`` for
  a uniform one, 0 for a one-hot).

The bin of a depth is always the one whose lifted point is nearest
(``nearest_bin``), whatever rounding the training target used: the
measure is where the features go.
"""
import math
from typing import Dict, Sequence

import torch
from torch import Tensor

from ..geometry.depth import (depth_bin_values, depth_to_bins,
                              normalize_depth_bound, num_depth_bins,
                              patch_min_depth)


class DepthBinAccuracy:
    """Accumulates the depth-bin statistics of many batches.

    Args:
        depth_bound (Sequence[float]): ``(min, max, step)`` of the bins in
            metres, the model's.
    """

    def __init__(self, depth_bound: Sequence[float]) -> None:
        self.depth_bound = normalize_depth_bound(depth_bound)
        self.num_bins = num_depth_bins(self.depth_bound)
        self._points = depth_bin_values(self.depth_bound).double()
        self._sums = dict(cells=0, top1=0, within_one_bin=0, prob_true=0.0,
                          expected_error_m=0.0, entropy=0.0)

    def update(self, depth: Tensor, gt_depth: Tensor) -> None:
        """Add the feature pixels of one batch that have a LiDAR depth.

        Args:
            depth (Tensor): Bin probabilities (after the softmax).
                Shape (M, D, h, w).
            gt_depth (Tensor): LiDAR depth maps, 0 where no return, at the
                network input's size. Shape (M, h * s, w * s) for an
                integer stride s.

        Raises:
            ValueError: If the shapes do not pair up.
        """
        if depth.dim() != 4 or depth.shape[1] != self.num_bins:
            raise ValueError(
                f'DepthBinAccuracy: expected depth of shape (M, '
                f'{self.num_bins}, h, w) for depth_bound {self.depth_bound},'
                f' got {tuple(depth.shape)}')
        num, _, feat_h, feat_w = depth.shape
        stride = gt_depth.shape[-1] // feat_w if gt_depth.dim() == 3 else 0
        if (stride < 1 or gt_depth.shape[0] != num
                or gt_depth.shape[-1] != feat_w * stride
                or gt_depth.shape[-2] != feat_h * stride):
            raise ValueError(
                f'DepthBinAccuracy: gt_depth {tuple(gt_depth.shape)} is not '
                f'depth {tuple(depth.shape)} at an integer stride')
        gt_depth = gt_depth.detach().cpu().float()
        target, valid = depth_to_bins(gt_depth, stride, self.depth_bound,
                                      nearest_bin=True)
        surface = patch_min_depth(gt_depth, stride).reshape(-1)[valid]
        probs = depth.detach().cpu().double().permute(0, 2, 3, 1).reshape(
            -1, self.num_bins)[valid]
        true_bin = target[valid].argmax(1)
        best = probs.argmax(1)
        sums = self._sums
        sums['cells'] += int(valid.sum())
        sums['top1'] += int((best == true_bin).sum())
        sums['within_one_bin'] += int(((best - true_bin).abs() <= 1).sum())
        sums['prob_true'] += float(probs.gather(1, true_bin[:, None]).sum())
        distance = (self._points[None, :] - surface.double()[:, None]).abs()
        sums['expected_error_m'] += float((probs * distance).sum())
        logs = torch.where(probs > 0, probs.log(), torch.zeros_like(probs))
        sums['entropy'] += float(-(probs * logs).sum())

    def summary(self) -> Dict[str, float]:
        """The statistics over everything added so far.

        Returns:
            dict[str, float]: ``cells``, ``top1`` and ``within_one_bin``
            (%), ``prob_true``, ``expected_error_m``, ``entropy`` (nats) and
            ``uniform_entropy`` (``ln D``, for comparison).

        Raises:
            ValueError: If no pixel with a LiDAR depth was added.
        """
        sums = self._sums
        cells = sums['cells']
        if cells == 0:
            raise ValueError('DepthBinAccuracy: no feature pixel with a '
                             'LiDAR depth inside the bins was added')
        return dict(
            cells=cells,
            top1=100.0 * sums['top1'] / cells,
            within_one_bin=100.0 * sums['within_one_bin'] / cells,
            prob_true=sums['prob_true'] / cells,
            expected_error_m=sums['expected_error_m'] / cells,
            entropy=sums['entropy'] / cells,
            uniform_entropy=math.log(self.num_bins))
