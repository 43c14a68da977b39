"""OccBEVAug and PointsToEgoFrame keep points, grid and cameras consistent.

The grid is 8 x 8 x 4 voxels of 0.5 m over x, y in [-2, 2], z in [-1, 1]:
voxel (i, j, k) has centre (-1.75 + 0.5 i, -1.75 + 0.5 j, -0.75 + 0.5 k).
"""
import numpy as np
import pytest
from mmdet3d.structures import LiDARPoints

from projects.occ_common.transforms.bev_aug import (OccBEVAug, bda_matrix,
                                                    resample_grid)
from projects.occ_common.transforms.frames import PointsToEgoFrame

RANGE = np.array([-2.0, -2.0, -1.0, 2.0, 2.0, 1.0])
VOXEL = np.array([0.5, 0.5, 0.5])


def _state():
    gt = np.zeros((8, 8, 4), np.uint8)
    gt[0, 1, 0] = 4  # centre (-1.75, -1.25, -0.75)
    gt[4, 4, 2] = 11  # centre (0.25, 0.25, 0.25)
    mask = gt > 0
    lidar2cam = np.array([[0.0, -1, 0, 0.5], [0, 0, -1, 0.2], [1, 0, 0, 0.1],
                          [0, 0, 0, 1]])
    return dict(
        points=LiDARPoints(
            np.array([[1.0, 2.0, 3.0, 0.5, 0.0]]), points_dim=5),
        gt_occ=gt,
        mask_camera=mask,
        occ_pc_range=RANGE,
        occ_voxel_size=VOXEL,
        cam2img=np.array([[[2.0, 0, 2, 0], [0, 2, 2, 0], [0, 0, 1, 0],
                           [0, 0, 0, 1]]]),
        lidar2cam=lidar2cam[None],
        img_aug_matrix=np.eye(4)[None],
        lidar2ego=np.eye(4))


def test_bda_matrix_by_hand():
    """Rotation by 90 deg maps (1, 2) to (-2, 1); flip_x then negates x:
    (2, 1); scale 2 doubles z too."""
    np.testing.assert_allclose(
        bda_matrix(90, 1, True, False) @ [1, 2, 3, 1], [2, 1, 3, 1],
        atol=1e-12)
    np.testing.assert_allclose(
        bda_matrix(0, 2, False, False) @ [1, 2, 3, 1], [2, 4, 6, 1])


@pytest.mark.parametrize('rotate, flip_x, flip_y, moved', [
    (90.0, False, False, (6, 0, 0)),  # (-1.75,-1.25) -> (1.25,-1.75)
    (0.0, True, False, (7, 1, 0)),  # x -> -x: (1.75, -1.25)
    (0.0, False, True, (0, 6, 0)),  # y -> -y: (-1.75, 1.25)
    (180.0, True, True, (0, 1, 0)),  # both undo the half turn
])
def test_exact_grid_moves_and_projection(rotate, flip_x, flip_y, moved):
    """The car voxel (0, 1, 0) moves to ``moved``; points move by bda and
    lidar2img @ (bda p) still equals the old lidar2img @ p."""
    state = _state()
    before = state['cam2img'][0] @ state['lidar2cam'][0] @ [1, 2, 3, 1]
    params = dict(rotate=rotate, scale=1.0, flip_x=flip_x, flip_y=flip_y)
    out = OccBEVAug().apply(state, params)
    assert out['gt_occ'][moved] == 4 and (out['gt_occ'] == 4).sum() == 1
    assert out['mask_camera'][moved] and out['mask_camera'].sum() == 2
    bda = bda_matrix(rotate, 1.0, flip_x, flip_y)
    np.testing.assert_allclose(out['bda_matrix'], bda)
    xyz = out['points'].tensor.numpy()[0, :3]
    np.testing.assert_allclose(xyz, (bda @ [1, 2, 3, 1])[:3], atol=1e-5)
    after = out['lidar2img'][0] @ np.append(xyz, 1)
    np.testing.assert_allclose(after, before, atol=1e-5)
    np.testing.assert_allclose(out['lidar2ego'], np.linalg.inv(bda))


def test_exact_path_equals_resampling():
    """For quarter turns and flips the fast permutation and the generic
    nearest-neighbour resampling agree voxel for voxel."""
    rng = np.random.default_rng(0)
    grid = rng.integers(0, 17, (8, 8, 4)).astype(np.uint8)
    for k in range(4):
        for fx in (False, True):
            state = dict(_state(), gt_occ=grid.copy())
            params = dict(rotate=90.0 * k, scale=1.0, flip_x=fx, flip_y=False)
            fast = OccBEVAug().apply(state, params)['gt_occ']
            slow = resample_grid(grid, bda_matrix(90 * k, 1, fx, False),
                                 RANGE, VOXEL, 255)
            np.testing.assert_array_equal(fast, slow)


def test_scale_and_angle_resample_with_ignore_outside():
    """Scale 2: the road voxel (4, 4, 2), spanning [0, 0.5]^2 x [0, 0.5],
    grows to [0, 1]^3 = voxels {4, 5} x {4, 5} x {2, 3}: 8 voxels of 11; the
    car voxel (0, 1, 0) moves to x in [-4, -3], out of the grid: no 4 left.
    Rotation by 45 deg: the target corner (7, 7, 0), centre (1.75, 1.75),
    comes from (1.75 sqrt(2), 0) = (2.47, 0), outside: 255, mask False."""
    out = OccBEVAug().apply(
        _state(), dict(rotate=0.0, scale=2.0, flip_x=False, flip_y=False))
    gt = out['gt_occ']
    assert (gt == 11).sum() == 8 and (gt[4:6, 4:6, 2:4] == 11).all()
    assert (gt == 4).sum() == 0
    out = OccBEVAug().apply(
        _state(), dict(rotate=45.0, scale=1.0, flip_x=False, flip_y=False))
    assert out['gt_occ'][7, 7, 0] == 255 and not out['mask_camera'][7, 7, 0]
    assert out['gt_occ'][4, 4, 2] == 11


def test_random_draw_and_test_mode():
    """test_mode keeps everything (bda = I); training with flips of
    probability 1 negates x and y; an empty grid stays empty."""
    out = OccBEVAug(test_mode=True)(_state())
    np.testing.assert_allclose(out['bda_matrix'], np.eye(4))
    state = _state()
    state['gt_occ'][:] = 0
    state['points'] = LiDARPoints(np.zeros((0, 5)), points_dim=5)
    out = OccBEVAug(flip_x_prob=1.0, flip_y_prob=1.0)(state)
    np.testing.assert_allclose(out['bda_matrix'], np.diag([-1, -1, 1, 1]))
    assert not out['gt_occ'].any() and len(out['points']) == 0
    with pytest.raises(ValueError, match='scale_range'):
        OccBEVAug(scale_range=(0, 1))
    assert 'rot90=False' in repr(OccBEVAug())


def test_points_to_ego_frame():
    """lidar2ego = translation (1, 0, 2): the point (1, 2, 3) moves to
    (2, 2, 5); lidar2ego becomes I and projections are unchanged; a second
    application raises."""
    state = _state()
    state['lidar2ego'] = np.eye(4)
    state['lidar2ego'][:3, 3] = [1.0, 0.0, 2.0]
    before = state['cam2img'][0] @ state['lidar2cam'][0] @ [1, 2, 3, 1]
    out = PointsToEgoFrame()(state)
    np.testing.assert_allclose(out['points'].tensor.numpy()[0, :3],
                               [2, 2, 5])
    np.testing.assert_allclose(out['lidar2ego'], np.eye(4))
    np.testing.assert_allclose(out['lidar2img'][0] @ [2, 2, 5, 1], before)
    assert out['coord_frame'] == 'ego'
    with pytest.raises(ValueError, match='twice'):
        PointsToEgoFrame()(out)
    assert repr(PointsToEgoFrame()) == 'PointsToEgoFrame()'


def test_rot90_draws_only_quarter_turns():
    """rot90=True (the benchmark's rot90 run) draws angles of exactly 0,
    90, 180 and 270 degrees, all four in 200 draws (each missing with
    probability (3/4)^200), and the draw turns the grid: the car voxel of
    ``_state`` leaves (0, 1, 0) whenever the angle is not 0. Without
    rot90 every angle is 0."""
    np.random.seed(0)
    aug = OccBEVAug(rot90=True, flip_x_prob=0.0, flip_y_prob=0.0)
    angles = {aug.sample_params()['rotate'] for _ in range(200)}
    assert angles == {0.0, 90.0, 180.0, 270.0}
    plain = OccBEVAug(flip_x_prob=0.0, flip_y_prob=0.0)
    assert {plain.sample_params()['rotate'] for _ in range(20)} == {0.0}
    for _ in range(8):
        out = aug(_state())
        turned = out['bda_params']['rotate'] != 0.0
        assert (out['gt_occ'][0, 1, 0] != 4) == turned
        assert (out['gt_occ'] == 4).sum() == 1
