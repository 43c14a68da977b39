"""The composed picture of a sample, and its PNG."""
import numpy as np
import pytest
import torch
from mmengine.structures import BaseDataElement
from PIL import Image

from projects.occ_common.synthetic.occ_inputs import ring_camera_rig
from projects.occ_common.visualization import (camera_images,
                                               render_data_sample,
                                               render_occ_figure, save_png)

NAMES = ('empty', 'car', 'road')
SMALL = dict(view_size=(60, 80), dpi=40)


def _grids():
    """GT: road floor and a 2x2x2 car; pred misses one car voxel."""
    gt = np.zeros((8, 8, 4), dtype=np.int64)
    gt[:, :, 0] = 2
    gt[3:5, 3:5, 1:3] = 1
    pred = gt.copy()
    pred[3, 3, 2] = 0
    return pred, gt


def test_pred_and_gt_give_three_columns_and_a_png(tmp_path):
    """Both grids -> GT, pred and error columns: wider than pred alone.

    Width in inches is 4 per column + 2.2 for the legend: 14.2 vs 6.2, at
    40 dpi 568 vs 248 pixels.
    """
    pred, gt = _grids()
    both = render_occ_figure(pred, gt, NAMES, **SMALL)
    alone = render_occ_figure(pred, None, NAMES, **SMALL)
    assert both.dtype == np.uint8 and both.shape[2] == 3
    assert (both.shape[1], alone.shape[1]) == (568, 248)
    path = save_png(both, str(tmp_path / 'sub' / 'fig.png'))
    with Image.open(path) as png:
        assert png.size == (both.shape[1], both.shape[0])
        assert png.mode == 'RGB'


def test_cameras_add_a_row():
    """Two 32x64 views (aspect 0.5) add 1 row x 4 * 3 / 3 * 0.5 = 2 in."""
    pred, gt = _grids()
    cam2img, lidar2cam = ring_camera_rig(2, (32, 64), 32.0)
    images = np.zeros((2, 32, 64, 3), dtype=np.uint8)
    plain = render_occ_figure(pred, gt, NAMES, **SMALL)
    with_cams = render_occ_figure(
        pred, gt, NAMES, images=images,
        lidar2img=(cam2img @ lidar2cam).numpy(),
        point_cloud_range=(-4, -4, -1, 4, 4, 1), voxel_size=(1, 1, 0.5),
        **SMALL)
    assert with_cams.shape[0] - plain.shape[0] == 2 * 40


def test_temporal_sample_draws_the_current_views():
    """A two-frame config packs 4 views (the current 2, then the previous
    2) with the 2 current projections: the picture is that of the current
    2 views alone (before: 'Expected lidar2img of shape (4, 4, 4)')."""
    pred, gt = _grids()
    cam2img, lidar2cam = ring_camera_rig(2, (32, 64), 32.0)
    sample = dict(pred_occ=pred, gt_occ=gt,
                  lidar2img=(cam2img @ lidar2cam).numpy(),
                  occ_pc_range=(-4, -4, -1, 4, 4, 1),
                  occ_voxel_size=(1, 1, 0.5))
    current = torch.full((2, 3, 32, 64), 200, dtype=torch.uint8)
    previous = torch.zeros((2, 3, 32, 64), dtype=torch.uint8)
    both = render_data_sample(sample, NAMES, 0,
                              img=torch.cat([current, previous]), **SMALL)
    alone = render_data_sample(sample, NAMES, 0, img=current, **SMALL)
    assert np.array_equal(both, alone)


def test_data_sample_with_tensors_renders():
    """A BaseDataElement with tensor grids and metainfo works as a dict."""
    pred, gt = _grids()
    sample = BaseDataElement(metainfo=dict(sample_idx=7))
    sample.pred_occ = torch.from_numpy(pred)
    sample.gt_occ = torch.from_numpy(gt)
    picture = render_data_sample(sample, NAMES, 0, **SMALL)
    assert picture.shape[1] == 568


def test_empty_grids_still_render():
    """All-empty pred and GT: blank views, no legend entries, no error."""
    empty = np.zeros((8, 8, 4), dtype=np.int64)
    picture = render_occ_figure(empty, empty, NAMES, **SMALL)
    assert picture.shape[1] == 568


def test_camera_images_are_converted_from_bgr():
    """Channels (B, G, R) = (10, 20, 30) -> RGB pixel (30, 20, 10)."""
    img = torch.tensor([10, 20, 30], dtype=torch.uint8).view(1, 3, 1, 1)
    assert camera_images(img).tolist() == [[[[30, 20, 10]]]]
    assert camera_images(img, bgr=False).tolist() == [[[[10, 20, 30]]]]
    with pytest.raises(ValueError, match=r'\(N, 3, H, W\)'):
        camera_images(torch.zeros(3, 4, 4))


def test_bad_inputs_are_named():
    """No grid, float labels, differing shapes, images without geometry."""
    pred, gt = _grids()
    with pytest.raises(ValueError, match='expected pred and/or gt'):
        render_occ_figure(None, None, NAMES)
    with pytest.raises(ValueError, match='pred_occ: expected integer'):
        render_occ_figure(pred.astype(float), gt, NAMES)
    with pytest.raises(ValueError, match='differ in shape'):
        render_occ_figure(pred[:4], gt, NAMES)
    with pytest.raises(ValueError, match='need lidar2img'):
        render_occ_figure(pred, gt, NAMES,
                          images=np.zeros((1, 4, 4, 3), dtype=np.uint8))
    with pytest.raises(ValueError, match='Sample 3 has no pred_occ'):
        render_data_sample(dict(sample_idx=3), NAMES, 0)
