"""tools/analysis_tools/lidar_visibility.py counts the voxels that hold a LiDAR
return.

A hand-made 2 x 2 x 1 grid of 1 m voxels from (0, 0, 0), labels
``[[1, 2], [2, 0]]`` (x down, y across), and points in voxels (0, 0) and
(1, 0) plus one outside the grid. Voxel centres lie 0.71, 1.58, 1.58 and
2.12 m from the origin horizontally.
"""
import json
import os.path as osp

import numpy as np
import pytest

from projects.occ_common.testing.tool_logs import load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
OCCCYL = osp.join(ROOT, 'configs', 'occ_cyl',
                  'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')
OCC = np.array([[1, 2], [2, 0]])[..., None]
RANGE = (0, 0, 0, 2, 2, 1)
POINTS = np.array([[0.5, 0.5, 0.5, 7.0], [1.2, 0.1, 0.9, 7.0],
                   [5.0, 5.0, 0.0, 7.0]])


def test_voxel_hits():
    """(0.5, 0.5, 0.5) is in voxel (0, 0, 0), (1.2, 0.1, 0.9) in (1, 0,
    0); (5, 5, 0) is outside and counts nowhere."""
    tool = load_tool('tools/analysis_tools/lidar_visibility.py')
    hit = tool.voxel_hits(OCC, POINTS, RANGE, (1, 1, 1))
    assert hit[..., 0].tolist() == [[True, False], [True, False]]


def test_count_per_label():
    """Label 1: its one voxel is hit and near (0.71 < 1 m). Label 2: of
    its two voxels (1.58 m each) the one at (1, 0) is hit: 50 %, none
    near. Label 0 ("empty"): not hit, 2.12 m. Label 2 has no name."""
    tool = load_tool('tools/analysis_tools/lidar_visibility.py')
    count = tool.VisibilityCount(RANGE, (1, 1, 1), near=1.0)
    count.update(OCC, POINTS)
    out = count.summary(['empty', 'one'])
    assert list(out) == ['empty', 'one', '2']
    assert out['one'] == pytest.approx(
        dict(voxels=1, with_return=100.0, near=100.0,
             mean_range_m=np.hypot(0.5, 0.5)))
    assert out['2'] == pytest.approx(
        dict(voxels=2, with_return=50.0, near=0.0,
             mean_range_m=np.hypot(0.5, 1.5)))
    assert out['empty'] == pytest.approx(
        dict(voxels=1, with_return=0.0, near=0.0,
             mean_range_m=np.hypot(1.5, 1.5)))
    # A second sample adds to the sums: label 1 twice, both hit.
    count.update(OCC, POINTS)
    assert count.summary(['empty', 'one'])['one']['voxels'] == 2


def test_command_line_on_the_tiny_world(converted_tiny_world, tmp_path):
    """The tiny world's val split (its one scene, 2 key frames) through
    the tiny OccCylindrical's test pipeline: every voxel of the two 200 x
    200 x 16 grids is counted once, the LiDAR hits the road, and almost no
    empty voxel holds a return (only a few, where a point lands in a cell
    the coarse label calls empty)."""
    tool = load_tool('tools/analysis_tools/lidar_visibility.py')
    out_json = tmp_path / 'vis.json'
    out = tool.main([
        OCCCYL, '--data-root', converted_tiny_world, '--json',
        str(out_json)
    ])
    assert sum(row['voxels'] for row in out.values()) == 2 * 200 * 200 * 16
    assert out['driveable_surface']['with_return'] > 10
    assert out['empty']['with_return'] < 1
    written = json.loads(out_json.read_text())
    assert written['split'] == 'val' and written['near_m'] == 20.0
    assert written['classes']['car'] == pytest.approx(out['car'])


def test_labels_of_another_grid_are_refused(converted_tiny_world):
    """A config of 0.4 m voxels over the same range (a 250 x 250 x 20
    grid) on the world's 200 x 200 x 16 labels: the error says which file
    and sample."""
    from mmengine.config import Config
    tool = load_tool('tools/analysis_tools/lidar_visibility.py')
    cfg = Config.fromfile(OCCCYL)
    cfg.voxel_size, cfg.grid_size = [0.4, 0.4, 0.4], [250, 250, 20]
    with pytest.raises(ValueError, match=r'nuscenes_occ_infos_val.pkl, '
                       r'sample 0: expected occupancy labels of the '
                       r"config's grid_size \(250, 250, 20\), got "
                       r'\(200, 200, 16\)'):
        tool.measure(cfg, data_root=converted_tiny_world)
