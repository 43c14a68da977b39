"""tools/misc/browse_occ.py: the one-file export of the tiny world and of
the real nuScenes key frame, and its refusals."""
import base64
import gzip
import json
import re

import numpy as np
import pytest

from projects.occ_common.analysis.real_sample import (MISSING_REASON,
                                                      real_info_file)
from projects.occ_common.testing.tool_logs import load_tool
from projects.occ_common.visualization.web import (ViewerAssetsMissing,
                                                   unpack_message,
                                                   viewer_script)

CONFIG = 'configs/sdg_occ/sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py'


@pytest.fixture(scope='module')
def tool():
    try:
        viewer_script()
    except ViewerAssetsMissing as err:
        pytest.skip(str(err))
    return load_tool('tools/misc/browse_occ.py')


def _embedded(path):
    """The samples an exported page holds: (meta, [(header, arrays,
    jpegs)])."""
    text = open(path, encoding='utf-8').read()
    found = re.search(r'id="occ-embedded">(.*?)</script>', text, re.S)
    data = json.loads(found.group(1).replace('<\\/', '</'))
    samples = []
    for entry in data['samples']:
        message = gzip.decompress(base64.b64decode(entry['message']))
        jpegs = [base64.b64decode(url.split(',', 1)[1])
                 for url in entry['images']]
        samples.append((*unpack_message(message), jpegs))
    return text, data['meta'], samples


def test_export_of_a_tiny_world_sample(tool, converted_tiny_world,
                                       tmp_path):
    """--export-html of sample 1: one file whose embedded sample is that
    key frame's Occ3D label (GT and both masks), with its key-frame points
    and six camera images, and the page script inline (no src=)."""
    out = str(tmp_path / 'sample1.html')
    sizes = tool.main([
        CONFIG, '--export-html', out, '--sample-idx', '1', '--cfg-options',
        f'test_dataloader.dataset.data_root={converted_tiny_world}'
    ])
    text, meta, samples = _embedded(out)
    assert sizes['file'] == len(text.encode())
    assert meta['num_samples'] == 1 and meta['empty_label'] == 17
    assert len(meta['class_names']) == 18
    assert '<script src=' not in text and CONFIG in text
    (header, arrays, jpegs), = samples
    infos = tool.build_samples(tool.parse_args([
        CONFIG, '--cfg-options',
        f'test_dataloader.dataset.data_root={converted_tiny_world}'
    ]), str(tmp_path)).dataset
    with np.load(infos.get_data_info(1)['occ_path']) as label:
        np.testing.assert_array_equal(
            arrays['gt'].reshape(200, 200, 16), label['semantics'])
        assert int(arrays['visibility'].sum()) == int(
            label['mask_camera'].sum() + 2 * label['mask_lidar'].sum())
    assert header['token'] == infos.get_data_info(1)['token']
    assert 'pred' not in arrays and len(jpegs) == 6
    assert header['counts']['points'] == len(arrays['points_label']) > 100


@pytest.mark.skipif(real_info_file() is None, reason=MISSING_REASON)
def test_export_of_the_real_key_frame(tool, tmp_path):
    """The real nuScenes key frame through --info-file (mmdet3d's info,
    converted as demo/occ_demo.py converts it): no labels, so no grid;
    its LiDAR points (34,688 in the file, less the ego vehicle's own
    returns) in the ego frame, and the six cameras, whose frusta start
    1-2 m from the ego origin at roof height."""
    out = str(tmp_path / 'real.html')
    tool.main([CONFIG, '--info-file', real_info_file(), '--export-html',
               out])
    _, _, ((header, arrays, jpegs), ) = _embedded(out)
    assert header['token'] == 'ca9a282c9e77460f8360f564131a8af5'
    assert header['grid']['shape'] is None and 'gt' not in arrays
    assert 20000 < header['counts']['points'] < 34688
    assert [c['name'] for c in header['cameras']] == [
        'CAM_FRONT', 'CAM_FRONT_RIGHT', 'CAM_FRONT_LEFT', 'CAM_BACK',
        'CAM_BACK_LEFT', 'CAM_BACK_RIGHT']
    centres = np.array([c['frustum'][0] for c in header['cameras']])
    assert (np.hypot(centres[:, 0], centres[:, 1]) < 2.5).all()
    assert ((centres[:, 2] > 1.3) & (centres[:, 2] < 2.0)).all()
    assert len(jpegs) == 6


def test_refusals_name_the_problem(tool, converted_tiny_world, capsys):
    root = f'test_dataloader.dataset.data_root={converted_tiny_world}'
    with pytest.raises(SystemExit, match=r'--sample-idx 7 is outside .*'
                       r'\(2 samples: 0..1\)'):
        tool.main([CONFIG, '--export-html', 'x.html', '--sample-idx', '7',
                   '--cfg-options', root])
    with pytest.raises(SystemExit, match='config not found: nope.py'):
        tool.main(['nope.py', '--export-html', 'x.html'])
    with pytest.raises(SystemExit):
        tool.parse_args([CONFIG, '--checkpoint', 'a', '--pred-dir', 'b'])
    assert 'not allowed with argument' in capsys.readouterr().err


def test_missing_node_modules_says_how_to_install(monkeypatch, tmp_path):
    from projects.occ_common.visualization.web import bundle
    monkeypatch.setenv(bundle.NODE_MODULES_ENV, str(tmp_path))
    with pytest.raises(ViewerAssetsMissing,
                       match='needs three in .*setup_browser.sh'):
        bundle.node_modules()
