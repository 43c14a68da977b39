"""The viewer in headless Chromium: the exported file and the served page,
judged by the pixels of screenshots.

The scene is an 8 x 8 x 4 grid of 1 m voxels (SurroundOcc labels): a road
floor (z = 0), a 2 x 2 x 2 car on it at x, y in 2..3, a vegetation column
at (6, 6, 1..3). The prediction differs in known voxels: the floor at
(0, 0, 0) is terrain (wrong class), the car's voxel (2, 2, 2) is missing
(false negative), a car voxel stands at (5, 1, 1) (false positive). The
top faces of the cubes show the palette colours exactly, so each colour is
counted as the screenshot's pixels within 4 of it per channel.
"""
import numpy as np
import pytest

from projects.occ_common.analysis.headless_chromium import (MISSING_REASON,
                                                            HeadlessChromium,
                                                            chromium_binary)
from projects.occ_common.visualization.palette import (ERROR_PALETTE,
                                                       SURROUNDOCC_CLASS_NAMES,
                                                       class_palette)
from projects.occ_common.visualization.web import (ViewerAssetsMissing,
                                                   ViewerServer, encode_sample,
                                                   export_html, viewer_meta,
                                                   viewer_script)

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(chromium_binary() is None, reason=MISSING_REASON)
]

CAR, ROAD, TERRAIN, VEGETATION = 4, 11, 14, 16
PALETTE = class_palette(SURROUNDOCC_CLASS_NAMES)
FP, FN, WRONG = 1, 2, 3
#: Pixels a colour needs to count as shown: a 1 m top face seen from
#: ~12 m in a 800 x 600 view covers hundreds.
SHOWN = 30


def _grids():
    gt = np.zeros((8, 8, 4), dtype=np.uint8)
    gt[:, :, 0] = ROAD
    gt[2:4, 2:4, 1:3] = CAR
    gt[6, 6, 1:4] = VEGETATION
    pred = gt.copy()
    pred[0, 0, 0] = TERRAIN
    pred[2, 2, 2] = 0
    pred[5, 1, 1] = CAR
    return gt, pred


def _sample(index: int):
    gt, pred = _grids()
    prob = np.full(gt.shape, 0.8, dtype=np.float32)
    if index == 1:  # the second sample: vegetation only, in the rain
        gt = np.where(gt == VEGETATION, gt, 0).astype(np.uint8)
        pred = gt.copy()
    # No camera sees the car's columns.
    mask_camera = np.ones(gt.shape, dtype=bool)
    mask_camera[2:4, 2:4] = False
    scene = dict(name=f'sample{index}', scene_name='scene-test',
                 is_rainy=index == 1, pc_range=[0, 0, 0, 8, 8, 4],
                 voxel_size=[1, 1, 1], forward='+x', gt_occ=gt,
                 pred_occ=pred, pred_prob=prob, mask_camera=mask_camera)
    return encode_sample(scene, len(SURROUNDOCC_CLASS_NAMES), 0)


def _meta(count: int):
    return viewer_meta(SURROUNDOCC_CLASS_NAMES, 0, count, title='test')


#: Left edge of the 3D view: the panel (290 px wide) shows every class's
#: colour in its swatches.
VIEW_LEFT = 300


def _shown(image: np.ndarray, rgb) -> int:
    """Pixels of the 3D view within 4 of ``rgb`` in every channel."""
    view = image[:, VIEW_LEFT:].astype(np.int16)
    diff = np.abs(view - np.asarray(rgb, np.int16))
    return int((diff <= 4).all(-1).sum())


@pytest.fixture(scope='module')
def script():
    try:
        return viewer_script()
    except ViewerAssetsMissing as err:
        pytest.skip(str(err))


@pytest.fixture(scope='module')
def browser():
    with HeadlessChromium(800, 600) as chromium:
        yield chromium


def _act(browser, expression: str):
    """Run a page action, then wait until its frame is on screen."""
    browser.evaluate(expression)
    browser.evaluate('window.occViewer.drawn()')
    return browser.screenshot()


def _open(browser, url: str, index: int = 0):
    """Open the page and look at the whole grid from 12 m behind and
    10 m above its near edge."""
    browser.navigate(url)
    browser.wait_for('document.body && document.body.dataset.state === '
                     f'"ready" && document.body.dataset.sample === '
                     f'"{index}"')
    browser.evaluate('window.occViewer.scene.setCamera([-12, 4, 10], '
                     '[4, 4, 0])')
    browser.evaluate('window.occViewer.drawn()')
    assert browser.page_errors() == []
    return browser.screenshot()


def test_exported_file_classes_toggles_and_errors(browser, script, tmp_path):
    """Offline file: the three classes' colours show; unticking ``car``
    removes its colour and keeps the others, and so does showing only
    what a camera sees (the car's columns are outside ``mask_camera``);
    the error view shows the
    false positive, false negative and wrong-class colours (and grey
    for the correct voxels); unticking false positives removes red. The
    page asks for nothing but its own file and data: URLs."""
    path = tmp_path / 'scene.html'
    sizes = export_html(str(path), _meta(1), [_sample(0)], script)
    assert sizes['file'] == path.stat().st_size
    image = _open(browser, path.as_uri())
    for label in (ROAD, CAR, VEGETATION):
        assert _shown(image, PALETTE[label]) > SHOWN, label
    image = _act(browser, 'document.getElementById("class-4").click()')
    assert _shown(image, PALETTE[CAR]) == 0
    assert _shown(image, PALETTE[ROAD]) > SHOWN
    assert _shown(image, PALETTE[VEGETATION]) > SHOWN
    browser.evaluate('document.getElementById("class-4").click()')
    # Only what a camera sees: the car goes, the road stays.
    image = _act(browser, 'const m = document.getElementById("mask-mode");'
                 'm.value = "camera"; m.dispatchEvent(new Event("change"))')
    assert _shown(image, PALETTE[CAR]) == 0
    assert _shown(image, PALETTE[ROAD]) > SHOWN
    browser.evaluate('window.occViewer.setMask("none")')
    image = _act(browser, 'document.getElementById("view-errors").click()')
    for code in (0, FP, FN, WRONG):
        assert _shown(image, ERROR_PALETTE[code]) > SHOWN, code
    assert _shown(image, PALETTE[ROAD]) == 0
    image = _act(browser, 'document.getElementById("error-1").click()')
    assert _shown(image, ERROR_PALETTE[FP]) == 0
    assert _shown(image, ERROR_PALETTE[FN]) > SHOWN
    schemes = {url.split(':')[0] for url in browser.requested_urls()}
    assert schemes <= {'file', 'data'}, schemes


def test_served_page_navigation_flags_and_readout(browser, script):
    """Served: sample 0 shows its classes; ``next`` loads sample 1 (only
    vegetation, rainy: the flag says so); hovering the top voxel of the
    vegetation column (6, 6, 3) reads its classes and the probability
    0.8 (stored as round(0.8 * 255) = 204: 204 / 255 = 0.80)."""
    server = ViewerServer(_meta(2), _sample, script, port=0)
    server.start_background()
    try:
        image = _open(browser, server.url)
        assert _shown(image, PALETTE[CAR]) > SHOWN
        browser.evaluate('document.getElementById("next").click()')
        browser.wait_for('document.body.dataset.sample === "1" && '
                         'document.body.dataset.state === "ready"')
        image = _act(browser, '0')
        assert _shown(image, PALETTE[CAR]) == 0
        assert _shown(image, PALETTE[VEGETATION]) > SHOWN
        assert 'rain' in browser.evaluate(
            'document.getElementById("flags").textContent')
        x, y = browser.evaluate(
            'window.occViewer.scene.screenPosition(6.5, 6.5, 3.99)')
        browser.mouse_move(x, y)
        readout = browser.wait_for(
            'document.getElementById("readout").textContent.includes('
            '"voxel (") && document.getElementById("readout").textContent')
        assert 'voxel (6, 6, 3)' in readout
        assert 'ground truth: vegetation (16)' in readout
        assert 'prediction: vegetation (16)  p = 0.80' in readout
        assert set(server.cache.sizes) == {0, 1}
    finally:
        server.shutdown()
        server.server_close()


def test_points_without_a_grid(browser, script, tmp_path):
    """A key frame without labels (the real sample's case): no voxels, no
    class list; its LiDAR points by lidarseg class show the class colours
    (a 20 x 20 patch of car points and one of vegetation points), by
    height neither."""
    xs, ys = np.meshgrid(np.linspace(1, 3, 20), np.linspace(1, 3, 20))
    patch = np.stack([xs.ravel(), ys.ravel(), np.full(400, 0.5)], 1)
    points = np.concatenate([patch, patch + [3, 3, 0]])
    labels = np.repeat([CAR, VEGETATION], 400)
    message = encode_sample(
        dict(name='frame', pc_range=[0, 0, 0, 8, 8, 4], voxel_size=[1] * 3,
             points=points, point_labels=labels), 17, 0)
    path = tmp_path / 'frame.html'
    export_html(str(path), _meta(1), [message], script)
    image = _open(browser, path.as_uri())
    assert browser.evaluate('document.querySelector("#class-4")'
                            '.closest("section").hidden')
    assert _shown(image, PALETTE[CAR]) == 0
    browser.evaluate('window.occViewer.state.pointSize = 6')
    image = _act(browser, 'window.occViewer.setPoints("class")')
    assert _shown(image, PALETTE[CAR]) > SHOWN
    assert _shown(image, PALETTE[VEGETATION]) > SHOWN
