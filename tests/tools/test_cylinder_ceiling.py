"""tools/analysis_tools/cylinder_ceiling.py scores the ground truth kept at the
majority class of each cylinder cell.

A hand-made 4 x 4 x 1 grid of 1 m voxels over ``[-2, 2]^2 x [0, 1]`` and
a cylinder of one ring, four azimuth sectors and one layer (radius 2 m,
clamped): sector ``j`` covers ``theta in [-pi + j pi / 2, -pi + (j + 1)
pi / 2)``, so each quadrant of the grid is one cell: x < 0, y < 0 is
sector 0, x > 0, y < 0 sector 1, x > 0, y > 0 sector 2, x < 0, y > 0
sector 3. Voxel (i, j) has its centre at (-1.5 + i, -1.5 + j).
"""
import json
import math
import os.path as osp

import numpy as np
import pytest

from projects.occ_common.testing.tool_logs import load_tool
from projects.occ_cyl.cylindrical import CylinderGrid

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
OCCCYL = osp.join(ROOT, 'configs', 'occ_cyl',
                  'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')
SDG = osp.join(ROOT, 'configs', 'sdg_occ',
               'sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py')
RANGE = (-2, -2, 0, 2, 2, 1)
SECTORS = CylinderGrid.for_box(RANGE, (1, 4, 1), radius='inscribed',
                               clamp=True)


def test_cells_are_the_quadrants():
    """Rows i = 0, 1 have x < 0; columns j = 0, 1 have y < 0."""
    tool = load_tool('tools/analysis_tools/cylinder_ceiling.py')
    cells = tool.cell_of_voxels((4, 4, 1), RANGE, (1, 1, 1), SECTORS)
    assert cells[..., 0].tolist() == [[0, 0, 3, 3], [0, 0, 3, 3],
                                      [1, 1, 2, 2], [1, 1, 2, 2]]


def test_majority_labels():
    """Quadrant x > 0, y > 0 (cell 2) holds 1, 1, 1, 2: all become 1.
    Cell 0 holds 255, 255, 3, 0: the unlabelled do not vote, 3 and 0 tie
    and the lower label wins, so the 3 becomes 0 and the 255s 0 too (the
    scoring skips them). Cell 1 holds only 255: the fill label 0. Cell 3
    holds 4, 4, 4, 0: 4."""
    tool = load_tool('tools/analysis_tools/cylinder_ceiling.py')
    occ = np.array([[255, 255, 4, 4], [3, 0, 4, 0], [255, 255, 1, 1],
                    [255, 255, 1, 2]])[..., None]
    cells = tool.cell_of_voxels((4, 4, 1), RANGE, (1, 1, 1), SECTORS)
    out = tool.majority_labels(occ, cells, 4, 5, 255, fill=0)
    assert out[..., 0].tolist() == [[0, 0, 4, 4], [0, 0, 4, 4],
                                    [0, 0, 1, 1], [0, 0, 1, 1]]
    # A voxel in no cell (-1) takes the fill label.
    cells[0, 2, 0] = -1
    out = tool.majority_labels(occ, cells, 4, 5, 255, fill=0)
    assert out[0, 2, 0] == 0 and out[0, 3, 0] == 4


def test_command_line_on_the_tiny_world(converted_tiny_world, tmp_path):
    """The tiny world's val split with one cell (1 x 1 x 1): every voxel
    takes the split-wide majority, empty, so no class is predicted: every
    occurring class scores 0, and so do IoU and mIoU. With the paper's
    480 x 368 x 32 cells most of the ground truth survives."""
    tool = load_tool('tools/analysis_tools/cylinder_ceiling.py')
    out_json = tmp_path / 'ceiling.json'
    out = tool.main([
        OCCCYL, '--shapes', '1x1x1', '480x368x32', '--data-root',
        converted_tiny_world, '--json',
        str(out_json)
    ])
    assert list(out) == ['1x1x1', '480x368x32']
    one = out['1x1x1']
    assert one['IoU'] == 0.0 and one['mIoU'] == 0.0
    present = [n for n, v in one['classes'].items() if not math.isnan(v)]
    assert 'driveable_surface' in present
    assert all(one['classes'][n] == 0.0 for n in present if n != 'empty')
    assert one['classes']['empty'] > 80
    assert out['480x368x32']['mIoU'] > 80
    written = json.loads(out_json.read_text())
    assert written['split'] == 'val'
    assert written['shapes']['480x368x32']['mIoU'] == pytest.approx(
        out['480x368x32']['mIoU'])


def test_default_is_the_configs_cylinder(converted_tiny_world):
    """Without --shapes the tiny config's own cylinder is measured."""
    from mmengine.config import Config
    tool = load_tool('tools/analysis_tools/cylinder_ceiling.py')
    cfg = Config.fromfile(OCCCYL)
    out = tool.measure(cfg, data_root=converted_tiny_world)
    assert list(out) == ['x'.join(map(str, cfg.model.cylinder.shape))]


def test_refusals():
    """A config without a cylinder, and a malformed shape."""
    from mmengine.config import Config
    tool = load_tool('tools/analysis_tools/cylinder_ceiling.py')
    with pytest.raises(ValueError, match='sdgocc-fusion_tiny.*model.cylind'):
        tool.measure(Config.fromfile(SDG))
    with pytest.raises(SystemExit):
        tool.parse_args([OCCCYL, '--shapes', '64x128'])
    with pytest.raises(Exception, match='RxThetaxZ'):
        tool.parse_shape('64x0x16')


def test_occ3d_needs_the_camera_mask(monkeypatch):
    """Under the occ3d convention only camera-visible voxels count; a
    sample without ``mask_camera`` is the metric's error naming it, not a
    silent count of nothing."""
    from mmengine.config import Config
    tool = load_tool('tools/analysis_tools/cylinder_ceiling.py')
    cfg = Config.fromfile(OCCCYL)
    cfg.test_evaluator.convention = 'occ3d'
    cfg.test_evaluator.use_camera_mask = True
    occ = np.zeros(tuple(cfg.grid_size), np.int64)
    monkeypatch.setattr(tool, 'labelled_samples',
                        lambda *a: iter([({'data_samples': {}}, occ)]))
    with pytest.raises(ValueError, match=r'sample val sample 0 has no '
                       r'mask_camera \(occ3d, use_camera_mask=True\)'):
        tool.measure(cfg)


def test_cfg_options_are_checked_as_in_test_py():
    """The analysis tools merge --cfg-options through apply_cfg_options:
    a string where the config has a list is refused, naming the key,
    before any data is read."""
    tool = load_tool('tools/analysis_tools/cylinder_ceiling.py')
    with pytest.raises(ValueError, match="grid_size='big'"):
        tool.main([OCCCYL, '--cfg-options', 'grid_size=big'])
