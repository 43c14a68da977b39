"""tools/analysis_tools/camera_visibility.py counts the pixels and grid cells
per class.

A hand-made 4 x 6 label map and a 2 x 3 grid of 2 x 2 cells::

    1 1 | 2 2 | 0 3
    1 2 | 2 2 | 3 0
    ----+-----+----
    4 4 | 0 0 | 5 5
    4 4 | 1 1 | 5 6

Cells: 1 (three of four), 2 (four), 0/3 tie (two each: the lower label,
0, wins), 4 (four), 0/1 tie (0 wins), 5 (three). Pixels: label 0 four,
1 five, 2 five, 3 two, 4 four, 5 three, 6 one (24 in all).
"""
import glob
import json
import os
import os.path as osp
import re

import numpy as np
import pytest

from projects.occ_common.testing.tool_logs import load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
OCCCYL = osp.join(ROOT, 'configs', 'occ_cyl',
                  'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')
LABELS = np.array([[1, 1, 2, 2, 0, 3],
                   [1, 2, 2, 2, 3, 0],
                   [4, 4, 0, 0, 5, 5],
                   [4, 4, 1, 1, 5, 6]])


def test_cell_majority_by_hand():
    """The module docstring's cells: labels 0 (two ties), 1, 2, 4 and 5
    win one or two cells; 3 and 6 none."""
    tool = load_tool('tools/analysis_tools/camera_visibility.py')
    won = tool.cell_majority(LABELS, (2, 3), 7)
    assert won.tolist() == [2, 1, 1, 0, 1, 1, 0]


def test_cell_edges_of_an_uneven_grid():
    """A 5-row image in 2 rows of cells: edges at round(2.5) = 2, so rows
    0-1 and 2-4. Column 0 is label 1 in rows 0-1 and label 2 below: the
    top cell goes to 1, the bottom one to 2."""
    tool = load_tool('tools/analysis_tools/camera_visibility.py')
    labels = np.array([[1], [1], [2], [2], [2]])
    assert tool.cell_majority(labels, (2, 1), 3).tolist() == [0, 1, 1]
    with pytest.raises(ValueError, match='a 6 x 1 grid does not fit a 5 x '
                       '1 image'):
        tool.cell_majority(labels, (6, 1), 3)


def test_count_sums_images():
    """Two copies of the map: pixel shares as in the docstring (label 1:
    5 / 24 = 20.83 %), cells doubled; a label out of range is refused
    with the image named."""
    tool = load_tool('tools/analysis_tools/camera_visibility.py')
    count = tool.CameraCount((2, 3), num_labels=7)
    count.update(LABELS)
    count.update(LABELS)
    out = count.summary('abcdefg')
    assert out['b'] == pytest.approx(dict(pixels=100 * 5 / 24, cells=2))
    assert out['a'] == pytest.approx(dict(pixels=100 * 4 / 24, cells=4))
    assert out['g'] == pytest.approx(dict(pixels=100 / 24, cells=0))
    assert count.images == 2
    with pytest.raises(ValueError, match=r'cam.png: expected a \(H, W\) '
                       r'map of labels in \[0, 7\), got shape \(4, 6\) '
                       r'with values 0\.\.7'):
        count.update(LABELS + (LABELS == 6), 'cam.png')


def test_command_line_on_the_tiny_world(converted_tiny_world, tmp_path):
    """The tiny world's val split (one scene, 2 key frames, six 160 x 90
    views each): every pixel and cell is counted once, and the driveable
    share is the share of raw class 24 (flat.driveable_surface, the only
    raw class of that occupancy class) counted straight from the maps."""
    from PIL import Image
    tool = load_tool('tools/analysis_tools/camera_visibility.py')
    out_json = tmp_path / 'cams.json'
    out = tool.main([
        OCCCYL, '--data-root', converted_tiny_world, '--cells', '6', '10',
        '--json', str(out_json)
    ])
    assert out['samples'] == 2 and out['images'] == 12
    rows = out['classes']
    assert list(rows)[:2] == ['sky/noise', 'barrier']
    assert sum(r['pixels'] for r in rows.values()) == pytest.approx(100)
    assert sum(r['cells'] for r in rows.values()) == 12 * 6 * 10
    maps = glob.glob(
        osp.join(converted_tiny_world, 'synthetic_gt', 'cam_labels', '*',
                 '*.png'))
    raw = np.stack([np.asarray(Image.open(p)) for p in maps])
    assert raw.shape == (12, 90, 160)  # the key frames' maps only
    road = 100 * np.mean(raw == 24)
    assert road > 1
    assert rows['driveable_surface']['pixels'] == pytest.approx(road)
    written = json.loads(out_json.read_text())
    assert written['split'] == 'val' and written['cells'] == [6, 10]
    assert written['classes']['car'] == pytest.approx(rows['car'])


def test_a_missing_map_is_named(world_copy):
    """Without the synthetic world's camera labels (a real nuScenes root)
    the error names the missing file and says what writes it."""
    tool = load_tool('tools/analysis_tools/camera_visibility.py')
    missing = sorted(
        glob.glob(
            osp.join(world_copy, 'synthetic_gt', 'cam_labels', 'CAM_FRONT',
                     '*.png')))[0]
    os.remove(missing)
    with pytest.raises(FileNotFoundError,
                       match=re.escape(osp.basename(missing)) +
                       ': no per-pixel class map; camera_visibility.py needs '
                       'a synthetic world'):
        tool.main([OCCCYL, '--data-root', world_copy])
