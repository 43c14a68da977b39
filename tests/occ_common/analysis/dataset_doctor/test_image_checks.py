"""The image measures of the calibration check on hand-made images.

The image: 100 x 200 pixels, dark (40) left of column 100 and bright (200)
right of it, so its only intensity edge is the vertical line at u = 100.
"""
import numpy as np
import pytest

from projects.occ_common.analysis.dataset_doctor.calibration import (
    rotation_error, transform_difference, unoccluded)
from projects.occ_common.analysis.dataset_doctor.edge_alignment import (
    edge_alignment, overlap_consistency, reflectivity_edges)

HEIGHT, WIDTH = 100, 200


def _image() -> np.ndarray:
    image = np.full((HEIGHT, WIDTH, 3), 40, np.uint8)
    image[:, WIDTH // 2:] = 200
    return image


def _scan_lines(edge_u: float):
    """Ten scan lines (rows 5, 15, ..., 95) of points every 2 pixels whose
    intensity jumps from 5 to 60 at ``edge_u``."""
    u, v = np.meshgrid(np.arange(1.0, WIDTH, 2.0),
                       np.arange(5.0, HEIGHT, 10.0))
    u, v = u.ravel(), v.ravel()
    return u, v, np.where(u < edge_u, 5.0, 60.0)


def test_reflectivity_edges_are_the_points_beside_a_jump():
    """60 > 3 * 5 + 5: on each line the last dark point (u = 99) and the
    first bright one (u = 101) are edge points: 20 in all; 10 vs 12 is no
    jump (12 < 3 * 10 + 5)."""
    u, v, intensity = _scan_lines(100.0)
    edge = reflectivity_edges(u, v, intensity, WIDTH, HEIGHT)
    assert edge.sum() == 20
    assert set(u[edge]) == {99.0, 101.0}
    flat = reflectivity_edges(u, v, np.where(u < 100, 10.0, 12.0), WIDTH,
                              HEIGHT)
    assert not flat.any()


def test_edge_alignment_is_high_on_the_edge_and_one_by_chance():
    """Points whose reflectivity jumps where the image does score far
    above 1 (every shifted copy lands on flat grey); a jump 10 pixels off
    the image's edge scores below 1 (the edge is only met by the copies
    moved 6 and 10 pixels); fewer than 30 edge points give no score."""
    u, v, intensity = _scan_lines(100.0)
    aligned = edge_alignment(_image(), u, v, intensity)
    assert aligned['edge_points'] == 20
    assert np.isnan(aligned['edge_alignment'])  # 20 < 30 edge points
    u2, v2, i2 = _scan_lines(100.0)
    v2 = np.concatenate([v2, v2 + 2])  # two rows per line: 40 edge points
    u2, i2 = np.concatenate([u2, u2]), np.concatenate([i2, i2])
    aligned = edge_alignment(_image(), u2, v2, i2)
    assert aligned['edge_points'] == 40
    assert aligned['edge_alignment'] > 10
    off = _scan_lines(90.0)
    u3, v3 = np.concatenate([off[0], off[0]]), np.concatenate(
        [off[1], off[1] + 2])
    i3 = np.concatenate([off[2], off[2]])
    assert edge_alignment(_image(), u3, v3, i3)['edge_alignment'] < 0.5


def test_overlap_consistency():
    """The same image seen at the same pixels correlates perfectly (1.0);
    the mirrored image, whose dark half is the other's bright one,
    perfectly negatively (-1.0); fewer than 20 shared points: NaN."""
    rng = np.random.default_rng(0)
    u = rng.uniform(0, WIDTH, 50)
    v = rng.uniform(0, HEIGHT, 50)
    same = overlap_consistency(_image(), _image(), (u, v), (u, v))
    assert same == dict(overlap_points=50.0,
                        overlap_consistency=pytest.approx(1.0))
    mirrored = overlap_consistency(_image(), _image()[:, ::-1], (u, v),
                                   (u, v))
    assert mirrored['overlap_consistency'] == pytest.approx(-1.0)
    few = overlap_consistency(_image(), _image(), (u[:5], v[:5]),
                              (u[:5], v[:5]))
    assert np.isnan(few['overlap_consistency'])


def test_rotation_checks():
    """A rotation has error ~0; a reflection inf; a matrix scaled by 1.01
    has error 2.01e-2 (1.01^2 - 1). Rotations of 90 deg about z and the
    identity differ by 90 deg; translations (1, 2, 2) apart by 3 m."""
    quarter = np.array([[0.0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 2],
                        [0, 0, 0, 1]])
    assert rotation_error(quarter) < 1e-12
    assert rotation_error(np.diag([1.0, 1, -1, 1])) == np.inf
    assert rotation_error(np.diag([1.01] * 3 + [1.0])) == pytest.approx(
        0.0201)
    deg, metres = transform_difference(quarter, np.eye(4))
    assert deg == pytest.approx(90.0) and metres == pytest.approx(3.0)


def test_unoccluded_keeps_the_nearest_points_of_a_cell():
    """Four points in one 5-pixel cell (a 200-pixel-wide image: cells of
    max(4, 200 / 40) = 5): depths 10, 10.5 and 11.3 (within 10 % + 0.3 m
    of 10) are seen, 20 is hidden; a point outside the view never is."""
    u = np.array([1.0, 2.0, 3.0, 4.0, 50.0])
    v = np.array([1.0, 1.0, 2.0, 3.0, 50.0])
    depth = np.array([10.0, 10.5, 11.3, 20.0, 5.0])
    inside = np.array([True, True, True, True, False])
    assert unoccluded(u, v, depth, inside, WIDTH).tolist() == [
        True, True, True, False, False]


def _camera_sample(points, recorded_lidar2img=None):
    """One camera looking along the LiDAR's +x (its down axis the LiDAR's
    -z), 200x100 pixels, fx = fy = 100, principal point at the centre; the
    LiDAR and the ego frame are one."""
    from projects.occ_common.analysis.dataset_doctor.sample_data import (
        CameraData, SampleData)
    cam2lidar = np.eye(4)
    cam2lidar[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]
    camera = CameraData(
        name='CAM', img_path='none.jpg',
        cam2img=np.array([[100.0, 0, 100, 0], [0, 100, 50, 0], [0, 0, 1, 0],
                          [0, 0, 0, 1]]),
        lidar2cam=np.linalg.inv(cam2lidar), cam2ego=cam2lidar,
        recorded_size=(100, 200), recorded_lidar2img=recorded_lidar2img)
    return SampleData(index=0, token='t', info={}, points=points,
                      lidar2ego=np.eye(4), ego2global=np.eye(4),
                      cameras=[camera])


def test_calibration_of_a_hand_made_camera():
    """Points 10 m ahead project into the image: median depth 10, the
    camera upright (down axis z -1), mounts and lidar2cam agree; the same
    points in millimetres lie 10,000 'm' away: a failure; a stored
    lidar2img off by 1 in one entry of largest entry 100 (0.01): a
    warning."""
    from projects.occ_common.analysis.dataset_doctor.calibration import \
        check_calibration
    points = np.array([[10.0, y, z, 1.0] for y in (-1, 0, 1)
                       for z in (-1, 0, 1)])
    good = check_calibration(_camera_sample(points))
    assert good.verdict == 'pass', good.findings
    assert good.numbers['CAM.median_depth'] == 10.0
    assert good.numbers['CAM.points_in_view'] == 9
    assert good.numbers['CAM.down_z'] == -1.0
    assert good.numbers['CAM.extrinsic_deg'] < 1e-6
    assert good.numbers['CAM.principal_x'] == 0.5
    millimetres = points.copy()
    millimetres[:, :3] *= 1000
    unit = check_calibration(_camera_sample(millimetres))
    assert unit.verdict == 'fail'
    assert unit.numbers['CAM.median_depth'] == 10000.0
    sample = _camera_sample(points)
    stale = sample.cameras[0].lidar2img.copy()
    stale[0, 3] += 1.0
    sample.cameras[0].recorded_lidar2img = stale
    warned = check_calibration(sample)
    assert warned.verdict == 'warn'
    assert warned.numbers['CAM.lidar2img_error'] == pytest.approx(0.01)
