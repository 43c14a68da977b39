"""MultiViewImageAug: the pixel map moves the pixels it claims to move."""
import numpy as np
import pytest

from projects.occ_common.transforms.image_aug import MultiViewImageAug


def _state(img):
    """One view with identity calibration: lidar2img = img_aug_matrix."""
    return dict(
        img=[img],
        cam2img=np.eye(4)[None],
        lidar2cam=np.eye(4)[None],
        img_aug_matrix=np.eye(4)[None])


def _dot(shape, row, col):
    img = np.zeros(shape + (3, ), np.uint8)
    img[row, col] = 200
    return img


def _mapped_pixel(mat, row, col):
    """Pixel that the centre (col + 0.5, row + 0.5) maps to."""
    u, v, _, _ = mat @ [col + 0.5, row + 0.5, 1.0, 1.0]
    return int(np.floor(v)), int(np.floor(u))


def test_test_mode_resize_matrix():
    """An 8x16 view to (4, 8): base scale max(4 / 8, 8 / 16) = 0.5, no
    crop slack, so img_aug_matrix = diag(0.5, 0.5, 1, 1) and lidar2img equals
    it (identity calibration)."""
    aug = MultiViewImageAug((4, 8), test_mode=True)
    out = aug(_state(np.zeros((8, 16, 3), np.uint8)))
    assert out['img'][0].shape == (4, 8, 3) and out['img_shape'] == (4, 8)
    np.testing.assert_allclose(out['img_aug_matrix'][0],
                               np.diag([0.5, 0.5, 1, 1]))
    np.testing.assert_allclose(out['lidar2img'][0], np.diag([.5, .5, 1, 1]))


@pytest.mark.parametrize(
    'params, expected',
    [
        # Flip of width 8: column 2 -> 8 - 1 - 2 = 5.
        (dict(flip=True, rotate=0.0, crop=(0.0, 0.0)), (1, 5)),
        # Crop 4 columns off the left: column 6 -> 2 (dot at (1, 6)).
        (dict(flip=False, rotate=0.0, crop=(4.0, 0.0)), (1, 2)),
    ])
def test_flip_and_crop_move_the_dot(params, expected):
    """A bright pixel lands where img_aug_matrix sends its centre."""
    col = 6 if params['crop'][0] else 2
    aug = MultiViewImageAug((4, 8) if not params['crop'][0] else (4, 4))
    img = _dot((4, 8), 1, col)
    out, mat = aug.augment(img, dict(resized=(4, 8), **params))
    hit = np.unravel_index(out[..., 0].argmax(), out.shape[:2])
    assert tuple(int(v) for v in hit) == expected
    mat4 = np.eye(4)
    mat4[:2, :2], mat4[:2, 2] = mat[:2, :2], mat[:2, 2]
    assert _mapped_pixel(mat4, 1, col) == expected


def test_rotation_90_moves_the_dot():
    """Turning a 4x4 view by 90 deg about (2, 2): the centre (1.5, 0.5) of
    pixel (row 0, col 1) goes to (2, 2) + R (-0.5, -1.5) with
    R = [[0, -1], [1, 0]], i.e. (2 + 1.5, 2 - 0.5) = (3.5, 1.5): row 1,
    col 3."""
    aug = MultiViewImageAug((4, 4))
    out, mat = aug.augment(
        _dot((4, 4), 0, 1),
        dict(resized=(4, 4), crop=(0.0, 0.0), flip=False, rotate=90.0))
    assert out[1, 3, 0] == 200 and out[..., 0].sum() == 200
    np.testing.assert_allclose(mat @ [1.5, 0.5, 1], [3.5, 1.5, 1])


def test_random_aug_keeps_projection_consistent():
    """Training draws: the pixel the matrix predicts for a dot is bright in
    the augmented 32x48 view (dot of 3x3 px to survive interpolation)."""
    np.random.seed(0)
    aug = MultiViewImageAug((32, 48),
                            resize_range=(0.9, 1.1),
                            rot_range=(-5, 5))
    img = np.zeros((64, 96, 3), np.uint8)
    img[30:33, 50:53] = 255
    for _ in range(5):
        out = aug(_state(img.copy()))
        row, col = _mapped_pixel(out['img_aug_matrix'][0], 31, 51)
        assert out['img'][0][row, col, 0] > 100
        assert out['img_aug_params'][0]['resized'][0] >= 29


def test_no_views_and_bad_args():
    """Zero views pass through; bad ranges raise naming the argument."""
    state = dict(img=[], cam2img=np.zeros((0, 4, 4)),
                 lidar2cam=np.zeros((0, 4, 4)),
                 img_aug_matrix=np.zeros((0, 4, 4)))
    assert MultiViewImageAug((4, 4))(state)['lidar2img'].shape == (0, 4, 4)
    with pytest.raises(ValueError, match='rot_range'):
        MultiViewImageAug((4, 4), rot_range=(5, -5))
    assert 'final_size=(4, 4)' in repr(MultiViewImageAug((4, 4)))
