"""Scores of labels against reference labels, on grids made by hand."""
import numpy as np
import pytest

from projects.occ_common.evaluation.label_quality import LabelQuality

SHAPE = (200, 200, 16)


def _occ3d(path, semantics, mask_lidar, mask_camera):
    np.savez_compressed(path, semantics=semantics,
                        mask_lidar=mask_lidar.astype(np.uint8),
                        mask_camera=mask_camera.astype(np.uint8))
    return str(path)


def test_scores_of_one_changed_voxel(tmp_path):
    """Reference: 10 car voxels (4) in a free grid, all in both masks,
    plus 10 free voxels in the LiDAR mask. Generated: the same with one
    car voxel free and its mask_lidar 1 voxel short. In the LiDAR mask
    (20 voxels): car IoU 9 / 10, free 10 / 11; geometry IoU 9 / 10; the
    mIoU of labels 0..16 is the car's alone (the others never occur).
    mask_lidar: 19 of 20 voxels shared, IoU 95 %, recall 95 %, precision
    100 %. Labels against themselves score 100."""
    semantics = np.full(SHAPE, 17, np.uint8)
    semantics[0, 0, :10] = 4
    lidar = np.zeros(SHAPE, bool)
    lidar[0, 0, :] = True
    lidar[0, 1, :4] = True
    camera = semantics != 17
    ref = _occ3d(tmp_path / 'ref.npz', semantics, lidar, camera)
    semantics[0, 0, 0] = 17
    lidar_short = lidar.copy()
    lidar_short[0, 1, 3] = False
    gen = _occ3d(tmp_path / 'gen.npz', semantics, lidar_short, camera)
    quality = LabelQuality()
    quality.add_occ3d(ref, gen)
    scores = quality.summary()
    in_lidar = scores['occ3d']['lidar_mask']
    assert in_lidar['IoU'] == pytest.approx(90.0)
    assert in_lidar['mIoU'] == pytest.approx(90.0)
    assert in_lidar['per_class'][17] == pytest.approx(100 * 10 / 11)
    assert scores['masks']['mask_lidar'] == pytest.approx(
        dict(IoU=95.0, recall=95.0, precision=100.0))
    same = LabelQuality()
    same.add_occ3d(ref, ref)
    assert same.summary()['occ3d']['grid']['mIoU'] == 100.0


def test_surroundocc_noise_ignored_in_reference_empty_in_generated(tmp_path):
    """Reference rows: voxel (0, 0, 0) car, (0, 0, 1) noise (ignored).
    Generated: (0, 0, 0) car, (0, 0, 2) noise: counted as empty, so it
    is no false positive. Geometry IoU and mIoU (car only): 100."""
    ref = tmp_path / 'ref.npy'
    np.save(ref, np.array([[0, 0, 0, 4], [0, 0, 1, 0]], np.int32))
    gen = tmp_path / 'gen.npy'
    np.save(gen, np.array([[0, 0, 0, 4], [0, 0, 2, 0]], np.int32))
    quality = LabelQuality()
    quality.add_surroundocc(str(ref), str(gen))
    scores = quality.summary()['surroundocc']
    assert scores['IoU'] == 100.0 and scores['mIoU'] == 100.0
    assert quality.surroundocc.sum() == 200 * 200 * 16 - 1
