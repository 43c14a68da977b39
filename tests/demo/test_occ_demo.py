"""demo/occ_demo.py: one sample in, its prediction file and picture out.

A checkpoint of the tiny OccCylindrical is trained in the test
(``tools/train.py``, one iteration on the tiny world), then the demo runs
on the real nuScenes key frame of ``../shared`` as a user runs it: the
mmdet3d v2 info file as it comes from mmdet3d, 1600x900 images, no labels.
"""
import os
import os.path as osp
import pickle

import numpy as np
import pytest
import torch
from PIL import Image

from projects.occ_common.analysis.real_sample import (INFO_FILE,
                                                      MISSING_REASON,
                                                      real_sample_dir)
from projects.occ_common.fileio.safe_pickle import (load_checkpoint_file,
                                                    load_info_file)
from projects.occ_common.testing.tool_logs import (REPO_ROOT, load_tool,
                                                   run_tool)

#: The tiny OccCylindrical: 96x160 network images (a 6x10 feature map), so
#: one CPU iteration takes about a second; it takes the real 1600x900
#: images through its own resize.
CONFIG = osp.join(REPO_ROOT, 'configs', 'occ_cyl',
                  'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')
#: SurroundOcc's classes: 'empty' and the 16 lidarseg classes.
NUM_CLASSES = 17
REAL_TOKEN = 'ca9a282c9e77460f8360f564131a8af5'


@pytest.fixture(scope='module')
def checkpoint(converted_tiny_world, tmp_path_factory):
    """The tiny config trained for one iteration (one epoch of the first
    training sample) with tools/train.py."""
    work = str(tmp_path_factory.mktemp('occ_demo_train'))
    data = [f'{split}_dataloader.dataset.data_root={converted_tiny_world}'
            for split in ('train', 'val', 'test')]
    proc = run_tool('tools/train.py', CONFIG, '--work-dir', work,
                    '--cfg-options', 'train_cfg.max_epochs=1',
                    'train_cfg.val_interval=2',
                    'default_hooks.checkpoint.interval=1',
                    'train_dataloader.dataset.indices=1', *data)
    assert proc.returncode == 0, proc.stderr[-3000:]
    path = osp.join(work, 'epoch_1.pth')
    assert osp.isfile(path)
    return path


def _demo():
    return load_tool('demo/occ_demo.py')


@pytest.mark.slow
@pytest.mark.skipif(real_sample_dir() is None, reason=MISSING_REASON)
def test_demo_on_the_real_sample(checkpoint, tmp_path):
    """The prediction of the real key frame, by token, from mmdet3d's info
    file: ``<token>.npz`` holds the (200, 200, 16) uint8 labels of the
    17 SurroundOcc classes; ``<token>.png`` is the one-column picture
    (prediction only) with the cameras: 4.0 in panel + 2.2 in legend =
    6.2 in wide, 7.0 in views + 0.4 in title + 2 rows x 4.0 / 3 in x
    96 / 160 (the network images' aspect) = 1.6 in cameras = 9.0 in high,
    at 100 dpi: 620 x 900 px. One printed line per file."""
    out = str(tmp_path / 'out')
    info = osp.join(real_sample_dir(), INFO_FILE)
    proc = run_tool('demo/occ_demo.py', CONFIG, checkpoint, info,
                    '--sample-token', REAL_TOKEN, '--out-dir', out,
                    '--device', 'cpu', timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    npz = osp.join(out, f'{REAL_TOKEN}.npz')
    png = osp.join(out, f'{REAL_TOKEN}.png')
    assert sorted(os.listdir(out)) == sorted(
        [osp.basename(npz), osp.basename(png)])
    with np.load(npz, allow_pickle=False) as data:
        grid = data['semantics']
    assert grid.dtype == np.uint8 and grid.shape == (200, 200, 16)
    assert int(grid.max()) < NUM_CLASSES
    with Image.open(png) as image:
        assert image.size == (620, 900)
        pixels = np.asarray(image.convert('RGB'))
    assert pixels.var() > 0
    lines = proc.stdout.strip().splitlines()
    assert f'prediction: {npz}' in lines
    assert f'picture: {png}' in lines


def test_sample_index_out_of_range_names_the_count(converted_tiny_world,
                                                   tmp_path):
    """The tiny world's val split holds its one scene's 2 key frames:
    index 2 is refused with the count and the valid range, in one line,
    before anything is built or written."""
    info = osp.join(converted_tiny_world, 'nuscenes_occ_infos_val.pkl')
    with pytest.raises(SystemExit) as exc:
        _demo().main([CONFIG, 'unused.pth', info, '--sample-idx', '2',
                      '--out-dir', str(tmp_path / 'out')])
    message = str(exc.value.code)
    assert message == (f'occ_demo.py: error: {info}: sample index 2 is out '
                       'of range: the file holds 2 samples (valid: 0..1)')
    assert not osp.exists(tmp_path / 'out')


def test_missing_info_file_names_the_path(tmp_path):
    """A nonexistent info file is named, with what was expected."""
    info = str(tmp_path / 'nuscenes_infos_val.pkl')
    with pytest.raises(SystemExit) as exc:
        _demo().main([CONFIG, 'unused.pth', info, '--out-dir',
                      str(tmp_path / 'out')])
    assert str(exc.value.code) == (
        f'occ_demo.py: error: info file not found: {info}; expected an '
        'info file of tools/create_data.py or an mmdet3d v2 info file '
        '(.pkl)')


def test_unknown_token_and_foreign_info_file(converted_tiny_world,
                                             tmp_path):
    """An unknown token names the file and its sample count; a pickle of
    neither info format names both expected formats."""
    info = osp.join(converted_tiny_world, 'nuscenes_occ_infos_val.pkl')
    with pytest.raises(SystemExit) as exc:
        _demo().main([CONFIG, 'unused.pth', info, '--sample-token', 'nope',
                      '--out-dir', str(tmp_path / 'out')])
    assert str(exc.value.code) == (
        f"occ_demo.py: error: {info}: no sample has the token 'nope' (it "
        'holds 2 samples)')
    foreign = str(tmp_path / 'foreign.pkl')
    with open(foreign, 'wb') as f:
        pickle.dump([dict(token='x')], f)
    with pytest.raises(SystemExit) as exc:
        _demo().main([CONFIG, 'unused.pth', foreign, '--out-dir',
                      str(tmp_path / 'out')])
    message = str(exc.value.code)
    assert message.startswith(f'occ_demo.py: error: {foreign}: expected an '
                              'info file of tools/create_data.py')
    assert 'mmdet3d v2 info file' in message and message.endswith(
        'got a list with keys []')


def test_missing_image_names_the_sample_and_path(converted_tiny_world,
                                                 tmp_path):
    """An info file whose CAM_BACK image is gone (another --data-root
    holding only the key frame): the error names the info file, the
    sample, the camera and the path."""
    info = osp.join(converted_tiny_world, 'nuscenes_occ_infos_val.pkl')
    entry = load_info_file(info)['data_list'][0]
    root = tmp_path / 'root'
    lidar = entry['lidar_points']['lidar_path']
    os.makedirs(root / osp.dirname(lidar))
    os.symlink(osp.join(converted_tiny_world, lidar), root / lidar)
    for cam, image in entry['images'].items():
        if cam != 'CAM_BACK':
            os.makedirs(root / osp.dirname(image['img_path']),
                        exist_ok=True)
            os.symlink(osp.join(converted_tiny_world, image['img_path']),
                       root / image['img_path'])
    with pytest.raises(SystemExit) as exc:
        _demo().main([CONFIG, 'unused.pth', info, '--data-root',
                      str(root), '--out-dir', str(tmp_path / 'out')])
    missing = osp.join(str(root), entry['images']['CAM_BACK']['img_path'])
    assert str(exc.value.code) == (
        f'occ_demo.py: error: {info}: sample {entry["token"]}: CAM_BACK '
        f'image not found: {missing} (check --data-root)')


@pytest.mark.slow
def test_checkpoint_of_another_model_is_refused(checkpoint, tmp_path,
                                                converted_tiny_world):
    """The trained state dict without its head's last tensor, and with
    one key of another model: both differences are named, nothing is
    written."""
    state = load_checkpoint_file(checkpoint, 'cpu')['state_dict']
    dropped = sorted(k for k in state
                     if not k.endswith('num_batches_tracked'))[-1]
    state.pop(dropped)
    state['other.weight'] = torch.zeros(1)
    bad = str(tmp_path / 'bad.pth')
    torch.save(dict(state_dict=state), bad)
    info = osp.join(converted_tiny_world, 'nuscenes_occ_infos_val.pkl')
    with pytest.raises(SystemExit) as exc:
        _demo().main([CONFIG, bad, info, '--out-dir',
                      str(tmp_path / 'out'), '--device', 'cpu'])
    message = str(exc.value.code)
    assert message.startswith(f'occ_demo.py: error: {bad} does not fit the '
                              f'model of {CONFIG}: 1 of the model')
    assert f'tensors are missing ({dropped})' in message
    assert "1 keys are not the model's (other.weight)" in message
    assert not osp.exists(tmp_path / 'out')
