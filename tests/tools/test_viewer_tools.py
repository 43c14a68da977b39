"""tools/misc/viewer_screenshot.py and
tools/analysis_tools/benchmark_viewer.py in headless Chromium."""
import numpy as np
import pytest
from PIL import Image

from projects.occ_common.analysis.headless_chromium import (MISSING_REASON,
                                                            chromium_binary)
from projects.occ_common.testing.tool_logs import load_tool
from projects.occ_common.visualization.palette import (ERROR_PALETTE,
                                                       class_palette,
                                                       convention_classes)
from projects.occ_common.visualization.web import (ViewerAssetsMissing,
                                                   encode_sample, export_html,
                                                   viewer_meta, viewer_script)

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(chromium_binary() is None, reason=MISSING_REASON)
]

CONFIG = 'configs/sdg_occ/sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py'


@pytest.fixture(scope='module')
def script():
    try:
        return viewer_script()
    except ViewerAssetsMissing as err:
        pytest.skip(str(err))


def _count(image: np.ndarray, rgb) -> int:
    view = image[:, 300:].astype(np.int16)  # right of the panel
    return int((np.abs(view - np.asarray(rgb)) <= 4).all(-1).sum())


def test_screenshot_of_an_export(script, tmp_path):
    """A 4 x 4 x 1 road floor (SurroundOcc label 11) predicted as terrain
    (14) but for one voxel: the default view shows road, --view errors
    the wrong-class colour and no road; --colours 0 keeps exact colours."""
    names, empty = convention_classes('surroundocc')
    gt = np.full((4, 4, 1), 11, dtype=np.uint8)
    pred = np.full_like(gt, 14)
    pred[0, 0, 0] = 11
    sample = encode_sample(dict(name='s', pc_range=[0, 0, 0, 4, 4, 1],
                                voxel_size=[1, 1, 1], gt_occ=gt,
                                pred_occ=pred), len(names), empty)
    page = str(tmp_path / 's.html')
    export_html(page, viewer_meta(names, empty, 1), [sample], script)
    tool = load_tool('tools/misc/viewer_screenshot.py')
    camera = ['--camera', '-4', '2', '6', '2', '2', '0']
    for name, extra in (('gt.png', []), ('errors.png', ['--view',
                                                        'errors'])):
        tool.main([page, str(tmp_path / name), '--size', '800', '600',
                   '--colours', '0', *camera, *extra])
    road = class_palette(names)[11]
    gt_image = np.asarray(Image.open(tmp_path / 'gt.png').convert('RGB'))
    errors = np.asarray(Image.open(tmp_path / 'errors.png').convert('RGB'))
    assert gt_image.shape == (600, 800, 3)
    assert _count(gt_image, road) > 1000
    assert _count(errors, road) == 0
    assert _count(errors, ERROR_PALETTE[3]) > 1000


def test_benchmark_reports_bytes_and_times(script, converted_tiny_world,
                                           tmp_path):
    """One round over sample 1 of the tiny world: the bytes reported are
    the server's (gzip smaller than raw, six JPEGs), the sample has a
    first and a median time, and the page raised no error."""
    report = load_tool('tools/analysis_tools/benchmark_viewer.py').main([
        '--samples', '1', '--rounds', '1', '--size', '640', '400',
        '--out', str(tmp_path / 'r.json'), CONFIG, '--cfg-options',
        f'test_dataloader.dataset.data_root={converted_tiny_world}'
    ])
    assert report['page_errors'] == []
    sample = report['samples'][1]
    assert 0 < sample['message_gzip'] < sample['message']
    assert sample['images'] > 0
    assert sample['first_ms'] > 0 and sample['shown_ms'] > 0
    assert report['export_bytes']['file'] > report['script_bytes']
    assert (tmp_path / 'r.json').is_file()
