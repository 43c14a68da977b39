"""Image, occupancy-label and lidarseg loaders on hand-made files."""
import cv2
import numpy as np
import pytest

from projects.occ_common.transforms import (LoadLidarSegLabels,
                                            LoadMultiViewImagesOcc,
                                            LoadOccupancyGT)

K = [[2.0, 0.0, 3.0], [0.0, 2.0, 2.0], [0.0, 0.0, 1.0]]


def _camera(tmp_path, name, shape=(4, 6, 3), value=0):
    path = str(tmp_path / f'{name}.png')
    cv2.imwrite(path, np.full(shape, value, np.uint8))
    lidar2cam = np.eye(4)
    lidar2cam[:3, 3] = [1.0, 0.0, 0.0]
    return dict(img_path=path, cam2img=K, lidar2cam=lidar2cam.tolist(),
                cam2ego=np.eye(4).tolist())


def test_multiview_images(tmp_path):
    """Two 4x6 views load in order with stacked (2, 4, 4) matrices.

    lidar2img = pad(K) @ lidar2cam: the point (0, 0, 1) goes to camera
    (1, 0, 1) and to (2 * 1 + 3 * 1, 2 * 0 + 2 * 1, 1) = (5, 2, 1).
    """
    images = dict(A=_camera(tmp_path, 'a', value=10),
                  B=_camera(tmp_path, 'b', value=20))
    out = LoadMultiViewImagesOcc(cam_names=['B', 'A'])(dict(images=images))
    assert [img[0, 0, 0] for img in out['img']] == [20, 10]
    assert out['img_shape'] == (4, 6) and out['num_views'] == 2
    assert out['lidar2img'].shape == (2, 4, 4)
    np.testing.assert_allclose(out['lidar2img'][0] @ [0, 0, 1, 1],
                               [5, 2, 1, 1])
    np.testing.assert_array_equal(out['img_aug_matrix'][1], np.eye(4))
    assert "cam_names=['B', 'A']" in repr(LoadMultiViewImagesOcc(['B', 'A']))


def test_multiview_image_errors(tmp_path):
    """A missing image and a view of another size name their files."""
    images = dict(A=_camera(tmp_path, 'a'), B=_camera(tmp_path, 'b'))
    images['B']['img_path'] = str(tmp_path / 'missing.jpg')
    with pytest.raises(FileNotFoundError, match='B image.*missing.jpg'):
        LoadMultiViewImagesOcc()(dict(images=images, token='t'))
    images['B'] = _camera(tmp_path, 'big', shape=(5, 6, 3))
    with pytest.raises(ValueError, match=r'big\.png has shape'):
        LoadMultiViewImagesOcc()(dict(images=images))


def test_surroundocc_label(tmp_path):
    """Rows (x, y, z, label): (0, 0, 0, 4) -> car 4; (199, 10, 15, 0) noise
    -> 255; (5, 6, 7, 16) -> 16; all other 200 * 200 * 16 - 3 voxels are
    empty (0). An empty (0, 4) file gives an all-empty grid."""
    path = str(tmp_path / 'x.pcd.bin.npy')
    np.save(path, np.array([[0, 0, 0, 4], [199, 10, 15, 0], [5, 6, 7, 16]]))
    out = LoadOccupancyGT('surroundocc')(dict(occ_path=path))
    gt = out['gt_occ']
    assert gt.shape == (200, 200, 16) and gt.dtype == np.uint8
    assert (gt[0, 0, 0], gt[199, 10, 15], gt[5, 6, 7]) == (4, 255, 16)
    assert np.count_nonzero(gt) == 3
    np.testing.assert_allclose(out['occ_pc_range'], [-50, -50, -5, 50, 50, 3])
    np.save(path, np.zeros((0, 4), np.int64))
    assert LoadOccupancyGT('surroundocc')(
        dict(occ_path=path))['gt_occ'].max() == 0


@pytest.mark.parametrize('array, msg', [
    (np.zeros((3, 3), np.int64), r'integer \(M, 4\).*\(3, 3\)'),
    (np.zeros((3, 4), np.float32), r'integer \(M, 4\).*float32'),
    (np.ones((3, 4), bool), r'integer \(M, 4\).*bool'),
    (np.array([[200, 0, 0, 1]]), r'voxel indices must lie in'),
])
def test_surroundocc_bad_label_names_file(tmp_path, array, msg):
    """Wrong shape, dtype or range: the error names the file."""
    path = str(tmp_path / 'bad.npy')
    np.save(path, array)
    with pytest.raises(ValueError, match=r'bad\.npy.*' + msg):
        LoadOccupancyGT('surroundocc')(dict(occ_path=path))


def _occ3d(path, **override):
    arrays = dict(
        semantics=np.full((200, 200, 16), 17, np.uint8),
        mask_lidar=np.zeros((200, 200, 16), np.uint8),
        mask_camera=np.zeros((200, 200, 16), np.uint8))
    arrays['semantics'][1, 2, 3] = 4
    arrays['semantics'][4, 5, 6] = 11
    arrays['mask_camera'][1, 2, 3] = 1
    arrays.update(override)
    np.savez_compressed(path, **arrays)


def test_occ3d_label_and_camera_mask(tmp_path):
    """semantics keeps 0..17; mask_with='camera' sets the one visible voxel
    (1, 2, 3) apart: 200 * 200 * 16 - 1 = 639999 voxels become 255."""
    path = str(tmp_path / 'labels.npz')
    _occ3d(path)
    out = LoadOccupancyGT('occ3d')(dict(occ_path=path))
    assert (out['gt_occ'][1, 2, 3], out['gt_occ'][4, 5, 6]) == (4, 11)
    assert out['mask_camera'].dtype == bool
    assert out['mask_camera'].sum() == 1 and out['mask_lidar'].sum() == 0
    masked = LoadOccupancyGT('occ3d', mask_with='camera')(
        dict(occ_path=path))['gt_occ']
    assert masked[1, 2, 3] == 4 and (masked == 255).sum() == 639999


def test_occ3d_bad_labels_name_file(tmp_path):
    """A missing array, a wrong shape, boolean semantics and a missing
    file name the file."""
    path = str(tmp_path / 'labels.npz')
    np.savez(path, semantics=np.zeros((200, 200, 16), np.uint8))
    with pytest.raises(ValueError, match=r'labels\.npz.*mask_lidar'):
        LoadOccupancyGT('occ3d')(dict(occ_path=path))
    _occ3d(path, semantics=np.zeros((200, 200, 8), np.uint8))
    with pytest.raises(ValueError, match=r'labels\.npz: semantics.*'
                       r'\(200, 200, 16\).*\(200, 200, 8\)'):
        LoadOccupancyGT('occ3d')(dict(occ_path=path))
    # Boolean semantics would pass as classes 0 / 1 (they did before).
    _occ3d(path, semantics=np.ones((200, 200, 16), bool))
    with pytest.raises(ValueError, match=r'labels\.npz: semantics must be '
                       'an integer array .* got bool'):
        LoadOccupancyGT('occ3d')(dict(occ_path=path))
    with pytest.raises(FileNotFoundError, match=r'gone\.npz'):
        LoadOccupancyGT('occ3d')(dict(occ_path=str(tmp_path / 'gone.npz')))
    with pytest.raises(ValueError, match='sample s1 has no occ3d'):
        LoadOccupancyGT('occ3d')(dict(occ_path=None, token='s1'))


def test_lidarseg_labels(tmp_path):
    """Raw classes (17 car, 0 noise, 24 driveable, 30 vegetation) map to
    (4, 255, 11, 16); a count mismatch with the key frame names the file;
    an empty file gives an empty label array."""
    path = str(tmp_path / 'tok_lidarseg.bin')
    np.array([17, 0, 24, 30], np.uint8).tofile(path)
    out = LoadLidarSegLabels()(dict(pts_semantic_mask_path=path))
    np.testing.assert_array_equal(out['pts_semantic_mask'], [4, 255, 11, 16])
    assert out['pts_semantic_mask'].dtype == np.int64
    with pytest.raises(ValueError, match=r'tok_lidarseg\.bin has 4 labels'):
        LoadLidarSegLabels()(
            dict(pts_semantic_mask_path=path, points=np.zeros((3, 5))))
    np.zeros(0, np.uint8).tofile(path)
    assert LoadLidarSegLabels()(
        dict(pts_semantic_mask_path=path))['pts_semantic_mask'].shape == (0, )
    with pytest.raises(FileNotFoundError, match=r'none\.bin'):
        LoadLidarSegLabels()(
            dict(pts_semantic_mask_path=str(tmp_path / 'none.bin')))


def test_lidarseg_labels_optional(tmp_path):
    """optional=True: a sample without a lidarseg path passes unchanged
    (no pts_semantic_mask); one whose label file is missing still names
    it. Not optional: the missing path is an error naming the sample."""
    state = dict(pts_semantic_mask_path=None, token='s3')
    assert LoadLidarSegLabels(optional=True)(dict(state)) == state
    with pytest.raises(ValueError, match='sample s3 has no lidarseg'):
        LoadLidarSegLabels()(dict(state))
    with pytest.raises(FileNotFoundError, match=r'gone\.bin'):
        LoadLidarSegLabels(optional=True)(
            dict(pts_semantic_mask_path=str(tmp_path / 'gone.bin')))
    assert 'optional=True' in repr(LoadLidarSegLabels(optional=True))


def test_unlabelled_sample_passes_only_when_allowed(tmp_path):
    """A test-split sample (info without a label path) is an error by
    default, naming the sample and the way out; with allow_unlabelled it
    gets the format's grid geometry and no gt_occ. A listed label that is
    missing stays an error either way."""
    sample = dict(occ_path=None, token='t1', ann_file='infos_test.pkl')
    with pytest.raises(ValueError, match='t1 has no occ3d.*--format-only'):
        LoadOccupancyGT('occ3d')(dict(sample))
    out = LoadOccupancyGT('occ3d', allow_unlabelled=True)(dict(sample))
    assert 'gt_occ' not in out and 'mask_camera' not in out
    np.testing.assert_allclose(out['occ_pc_range'],
                               [-40, -40, -1, 40, 40, 5.4])
    np.testing.assert_allclose(out['occ_voxel_size'], [0.4, 0.4, 0.4])
    with pytest.raises(FileNotFoundError, match='gone.npy'):
        LoadOccupancyGT('surroundocc', allow_unlabelled=True)(
            dict(occ_path=str(tmp_path / 'gone.npy')))
