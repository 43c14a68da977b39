"""PackOccInputs and batching by mmdet3d's Det3DDataPreprocessor."""
import numpy as np
import torch
from mmdet3d.models.data_preprocessors import Det3DDataPreprocessor
from mmdet3d.structures import LiDARPoints
from mmengine.dataset import pseudo_collate

from projects.occ_common.transforms.formatting import PackOccInputs


def _results(num_points, views=2, size=(4, 6)):
    height, width = size
    imgs = [
        np.full((height, width, 3), 10 * (v + 1), np.uint8)
        for v in range(views)
    ]
    gt = np.zeros((8, 8, 4), np.uint8)
    gt[1, 2, 3] = 4
    depth = np.zeros((views, height, width), np.float32)
    depth[0, 1, 1] = 2.5
    return dict(
        points=LiDARPoints(
            np.arange(num_points * 5, dtype=np.float32).reshape(-1, 5),
            points_dim=5),
        img=imgs,
        gt_occ=gt,
        mask_camera=gt > 0,
        gt_depth=depth,
        gt_seg_2d=np.full((views, height, width), 255, np.uint8),
        pts_semantic_mask=np.arange(num_points, dtype=np.int64),
        lidar2img=np.tile(np.eye(4), (views, 1, 1)),
        img_shape=size,
        token='tok',
        is_rainy=True,
        bda_matrix=np.eye(4))


def test_pack_fields_and_dtypes():
    """3 points, two 4x6 views: img (2, 3, 4, 6), points (3, 5); gt_occ long
    with the car voxel (1, 2, 3) = 4; mask bool; depth (2, 4, 6) float;
    lidar2img metainfo float32 (2, 4, 4)."""
    packed = PackOccInputs()(_results(3))
    inputs, sample = packed['inputs'], packed['data_samples']
    assert inputs['img'].shape == (2, 3, 4, 6)
    assert inputs['img'][1, 0, 0, 0] == 20
    assert inputs['points'].shape == (3, 5)
    assert sample.gt_occ.dtype == torch.long and sample.gt_occ[1, 2, 3] == 4
    assert sample.mask_camera.dtype == torch.bool
    assert sample.mask_camera.sum() == 1
    assert sample.gt_depth[0, 1, 1] == 2.5
    assert sample.gt_seg_2d.dtype == torch.uint8
    assert sample.gt_pts_seg.pts_semantic_mask.tolist() == [0, 1, 2]
    assert sample.metainfo['lidar2img'].dtype == np.float32
    assert sample.token == 'tok' and sample.is_rainy
    assert 'gt_occ' in repr(PackOccInputs())


def test_batch_collates_and_targets_backpropagate():
    """Two samples (3 and 0 points) collate to imgs (2, 2, 3, 4, 6) and a
    list of points; a loss between a learnable map and the packed depth
    targets backpropagates: L = sum over the one hit pixel (2.5 - 0)^2 =
    6.25 per sample, dL/dx = -2 * 2.5 = -5 at that pixel."""
    batch = pseudo_collate([PackOccInputs()(_results(3)),
                            PackOccInputs()(_results(0))])
    pre = Det3DDataPreprocessor(mean=[0, 0, 0], std=[1, 1, 1])
    out = pre(batch)
    assert out['inputs']['imgs'].shape == (2, 2, 3, 4, 6)
    assert [len(p) for p in out['inputs']['points']] == [3, 0]
    samples = out['data_samples']
    target = torch.stack([s.gt_depth for s in samples])
    pred = torch.zeros_like(target, requires_grad=True)
    valid = target > 0
    loss = ((pred - target)[valid]**2).sum()
    loss.backward()
    assert loss.item() == 2 * 6.25
    assert pred.grad[0, 0, 1, 1] == -5.0 and pred.grad.abs().sum() == 10.0
