"""tools/misc/visualize_occ.py and tools/test.py --show-dir on the toy
config."""
import glob
import os
import os.path as osp
import subprocess
import sys

import numpy as np
import pytest
import torch
from PIL import Image

from projects.occ_common.fileio import load_checkpoint_file
from projects.occ_common.testing.tool_logs import load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


def _toy_checkpoint(path):
    """A seeded, untrained toy model saved as a Runner-style checkpoint."""
    from projects.occ_common.testing.toy_model import ToyOccupancyModel
    torch.manual_seed(0)
    model = ToyOccupancyModel(in_channels=3, num_classes=3)
    torch.save({'meta': {}, 'state_dict': model.state_dict()}, path)
    return model


def _png_size(path):
    with Image.open(path) as png:
        return png.size


def test_from_saved_npz_and_npy(tmp_path):
    """pred + GT in one .npz: three columns; a dense .npy alone: one."""
    gt = np.zeros((8, 8, 4), dtype=np.uint8)
    gt[:, :, 0] = 11  # driveable_surface in SurroundOcc labels
    pred = gt.copy()
    pred[0, 0, 0] = 0
    np.savez(tmp_path / 's.npz', pred_occ=pred, gt_occ=gt)
    np.save(tmp_path / 'p.npy', pred)
    tool = load_tool('tools/misc/visualize_occ.py')
    both = tool.main(['--pred', str(tmp_path / 's.npz'), '--out',
                      str(tmp_path / 'both.png'), '--view-size', '40', '60'])
    alone = tool.main(['--pred', str(tmp_path / 'p.npy'), '--out',
                       str(tmp_path / 'alone.png'), '--view-size', '40',
                       '60'])
    assert _png_size(both)[0] > 2 * _png_size(alone)[0]


#: A --pred file name of 112 characters, as a scene, a token and a run
#: name make one.
LONG_NAME = ('scene-0061_ca9a282c9e77460f8360f564131a8af5_occcyl_r50-swint_'
             '3xb1-24e_surroundocc-nus_epoch_24_prediction_and_gt')


def _ink_columns(png):
    """Columns of the picture holding dark (text) pixels."""
    with Image.open(png) as image:
        grey = np.asarray(image.convert('L'))
    return np.flatnonzero((grey < 128).any(0))


@pytest.mark.parametrize('grids', [('pred_occ', ), ('pred_occ', 'gt_occ')])
def test_long_title_is_inside_the_picture(grids, tmp_path):
    """--pred with a long file name: the title 'sample NAME' (119
    characters, 1,028 px of 11 pt DejaVu Sans) in one column (6.2 in at
    100 dpi = 620 px), or 'sample NAME   wrong voxels: ...' (185
    characters, 1,510 px) in three (14.2 in = 1,420 px), is wider than the
    picture. It used to be centred on one line and cut at both sides (ink
    in the first and last columns); now it is wrapped, and the 5 px at
    each side stay blank."""
    gt = np.zeros((8, 8, 4), dtype=np.uint8)
    gt[:, :, 0] = 11
    np.savez(tmp_path / f'{LONG_NAME}.npz',
             **{key: gt for key in grids})
    out = load_tool('tools/misc/visualize_occ.py').main(
        ['--pred', str(tmp_path / f'{LONG_NAME}.npz'), '--out',
         str(tmp_path / 'long.png'), '--view-size', '40', '60'])
    width = _png_size(out)[0]
    assert width == (620 if len(grids) == 1 else 1420)
    ink = _ink_columns(out)
    assert ink.min() >= 5 and ink.max() < width - 5, (ink.min(), ink.max())


def test_wrapped_title_lies_within_the_figure_above_the_panels():
    """The title's extent (matplotlib's renderer) is inside the figure,
    3 px clear of each side, and above every panel's own title; a short
    title keeps one line and the picture its size (6.2 x 7.4 in).

    One column: a line has (6.2 - 2 * 0.15) in * 100 dpi = 590 px. In 11 pt
    DejaVu Sans 'x' is 9 px, 'sample ' 60 px, 'long' 33 px and ' long'
    38 px: line 1 is 'sample ' + 40 x + 4 ' long' = 60 + 360 + 152 = 572 px
    (a fifth: 610 px); then 'long' + 14 ' long' = 33 + 532 = 565 px per
    line (a 16th word: 603 px), so the other 56 words take 15 + 15 + 15 +
    11: 5 lines.
    """
    from projects.occ_common.visualization import occ_figure
    image = np.zeros((8, 8, 3), np.uint8)
    views = {'Prediction': (image, image)}
    long_heading = 'sample ' + 'x' * 40 + ' long' * 60
    for heading, lines in (('sample 0', 1), (long_heading, 5)):
        fig = occ_figure._figure(views, None, [], heading, 100)
        renderer = fig.canvas.get_renderer()
        title = fig.texts[0]
        box = title.get_window_extent(renderer)
        assert title.get_text().count('\n') + 1 == lines
        assert 3 <= box.x0 and box.x1 <= fig.bbox.width - 3
        assert box.y1 <= fig.bbox.height
        assert all(box.y0 > ax.title.get_window_extent(renderer).y1
                   for ax in fig.axes if ax.get_title())
        if lines == 1:
            assert tuple(fig.get_size_inches()) == pytest.approx((6.2, 7.4))


def test_sparse_surroundocc_and_occ3d_labels(tmp_path):
    """(N, 4) rows become a dense grid; Occ3D 'semantics' is the GT."""
    tool = load_tool('tools/misc/visualize_occ.py')
    rows = np.array([[0, 0, 0, 4], [7, 7, 3, 16]])
    dense = tool.sparse_to_dense(rows, (8, 8, 4), 'x.npy')
    assert dense[0, 0, 0] == 4 and dense[7, 7, 3] == 16
    assert dense.sum() == 20
    with pytest.raises(ValueError, match=r'x.npy: voxel \[7, 7, 3\]'):
        tool.sparse_to_dense(rows, (4, 4, 4), 'x.npy')
    semantics = np.full((8, 8, 4), 17, dtype=np.uint8)
    semantics[:, :, 0] = 11
    np.savez(tmp_path / 'labels.npz', semantics=semantics,
             mask_camera=np.ones((8, 8, 4), bool))
    out = tool.main(['--gt', str(tmp_path / 'labels.npz'), '--convention',
                     'occ3d', '--out', str(tmp_path / 'gt.png'),
                     '--view-size', '40', '60'])
    assert osp.isfile(out)
    np.savez(tmp_path / 'other.npz', logits=semantics)
    with pytest.raises(ValueError, match="expected an array 'pred_occ'"):
        tool.main(['--pred', str(tmp_path / 'other.npz'), '--out',
                   str(tmp_path / 'x.png')])


class _RunsCode:
    """Unpickling this would create ``marker``."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (open, (self.marker, 'w'))


def test_occ3d_submission_and_flashocc_files(tmp_path):
    """An Occ3D submission file (tools/test.py --format-only: 'semantics'
    and 'arr_0') and FlashOcc's pred.npz ('pred', with its GT as a pickled
    object) are read as predictions with the Occ3D convention; the pickle
    is never loaded (the object would create a file), and a FlashOcc file
    is no GT."""
    from projects.occ_common.evaluation.occupancy_export import \
        write_occ3d_prediction
    tool = load_tool('tools/misc/visualize_occ.py')
    semantics = np.full((8, 8, 4), 17, dtype=np.uint8)
    semantics[:, :, 0] = 11
    pred = semantics.copy()
    pred[0, 0, 0] = 17
    sub = write_occ3d_prediction(str(tmp_path / 'sub'), 'tok', pred)
    np.savez(tmp_path / 'labels.npz', semantics=semantics,
             mask_camera=np.ones((8, 8, 4), bool),
             mask_lidar=np.ones((8, 8, 4), bool))
    grids = tool.load_grid(sub, 'pred_occ', (8, 8, 4))
    assert grids['convention'] == 'occ3d'
    np.testing.assert_array_equal(grids['pred_occ'], pred)
    marker = tmp_path / 'pwned'
    flash = tmp_path / 'pred.npz'
    np.savez_compressed(flash, pred=pred,
                        gt=np.array(_RunsCode(str(marker)), dtype=object),
                        sample_token='tok')
    grids = tool.load_grid(str(flash), 'pred_occ', (8, 8, 4))
    assert sorted(grids) == ['convention', 'pred_occ']
    np.testing.assert_array_equal(grids['pred_occ'], pred)
    with pytest.raises(ValueError, match="FlashOcc 'pred'"):
        tool.load_grid(str(flash), 'gt_occ', (8, 8, 4))
    out = tool.main(['--pred', str(flash), '--gt',
                     str(tmp_path / 'labels.npz'), '--out',
                     str(tmp_path / 'flash.png'), '--view-size', '40', '60'])
    alone = tool.main(['--pred', sub, '--out', str(tmp_path / 'sub.png'),
                       '--view-size', '40', '60'])
    # GT, prediction and error map: three columns against one.
    assert _png_size(out)[0] > 2 * _png_size(alone)[0]
    assert not marker.exists()


def test_from_config_checkpoint_and_index(tmp_path):
    """Sample 2 of the toy test split; --save-pred stores argmax exactly.

    The stored prediction equals argmax over classes of the toy model's
    1x1x1 convolution applied to that sample's features.
    """
    model = _toy_checkpoint(tmp_path / 'toy.pth')
    tool = load_tool('tools/misc/visualize_occ.py')
    tool.main(['--config', CONFIG, '--checkpoint', str(tmp_path / 'toy.pth'),
               '--index', '2', '--out', str(tmp_path / 'two.png'),
               '--save-pred', str(tmp_path / 'two.npz'), '--view-size', '40',
               '60'])
    from projects.occ_common.testing.toy_model import ToyOccupancyDataset
    info = ToyOccupancyDataset(num_samples=4, seed=100).get_data_info(2)
    with torch.no_grad():
        expected = model(info['inputs'][None]).argmax(1)[0].numpy()
    with np.load(tmp_path / 'two.npz') as saved:
        np.testing.assert_array_equal(saved['pred_occ'], expected)
        np.testing.assert_array_equal(saved['gt_occ'], info['gt_occ'])
    assert osp.isfile(tmp_path / 'two.png')
    with pytest.raises(ValueError, match=r'--index 9 .* \(4 samples\)'):
        tool.main(['--config', CONFIG, '--checkpoint',
                   str(tmp_path / 'toy.pth'), '--index', '9', '--out',
                   str(tmp_path / 'x.png')])
    with pytest.raises(SystemExit):
        tool.parse_args(['--config', CONFIG, '--out', 'x.png'])


def test_checkpoint_of_another_model_is_refused(tmp_path):
    """Another model's checkpoint (renamed classifier): refused, naming
    the file and the key (before: logger='silent' loaded nothing of it
    and drew a randomly initialised model), unless --allow-key-mismatch."""
    _toy_checkpoint(tmp_path / 'toy.pth')
    checkpoint = load_checkpoint_file(str(tmp_path / 'toy.pth'))
    state = checkpoint['state_dict']
    state['head.weight'] = state.pop('classifier.weight')
    other = str(tmp_path / 'other.pth')
    torch.save(checkpoint, other)
    tool = load_tool('tools/misc/visualize_occ.py')
    argv = ['--config', CONFIG, '--checkpoint', other, '--out',
            str(tmp_path / 'x.png'), '--view-size', '40', '60']
    with pytest.raises(ValueError, match=r'other\.pth does not fit the model'
                       r'.*missing \(classifier.weight\).*'
                       '--allow-key-mismatch'):
        tool.main(argv)
    tool.main(argv + ['--allow-key-mismatch'])
    assert osp.isfile(tmp_path / 'x.png')


def test_cfg_options_of_the_wrong_kind_end_in_one_line(tmp_path, capsys):
    """Checked as tools/test.py checks them: status 2 and one line (before:
    mmengine's DictAction merged 'abc' and building the model's Conv3d
    raised a TypeError traceback)."""
    _toy_checkpoint(tmp_path / 'toy.pth')
    tool = load_tool('tools/misc/visualize_occ.py')
    with pytest.raises(SystemExit) as err:
        tool.main(['--config', CONFIG, '--checkpoint',
                   str(tmp_path / 'toy.pth'), '--out',
                   str(tmp_path / 'x.png'), '--cfg-options',
                   'model.num_classes=abc'])
    assert err.value.code == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].endswith(
        ": error: --cfg-options of the wrong kind: model.num_classes='abc' "
        '(a string), but the config has the integer 3 there'), lines
    assert not osp.exists(tmp_path / 'x.png')


#: A toy dataset whose samples carry the identity the nuScenes infos give
#: (``token``, ``scene_name``): even samples both, odd ones a token only.
NAMED_TOY = """
from mmdet3d.registry import DATASETS

from projects.occ_common.testing.toy_model import ToyOccupancyDataset


@DATASETS.register_module()
class NamedToyOccupancyDataset(ToyOccupancyDataset):

    def prepare_data(self, idx):
        data = super().prepare_data(idx)
        meta = dict(token=f'token{idx}')
        if idx % 2 == 0:
            meta['scene_name'] = 'scene-0001'
        data['data_samples'].set_metainfo(meta)
        return data
"""


@pytest.mark.slow
def test_test_py_show_dir_writes_one_png_per_sample(tmp_path):
    """tools/test.py --show-dir: 4 val samples -> one picture each, named
    ``<scene_name>_<token>.png`` or ``<token>.png`` (before: 0.png ..
    3.png, the sample_idx).

    The pictures land in {work_dir}/{timestamp}/show, as mmdet3d's
    --show-dir help says.
    """
    _toy_checkpoint(tmp_path / 'toy.pth')
    (tmp_path / 'named_toy.py').write_text(NAMED_TOY)
    config = tmp_path / 'named_toy_occ.py'
    config.write_text(
        f"_base_ = [{CONFIG!r}]\n"
        "custom_imports = dict(imports=['projects.occ_common', "
        "'projects.occ_common.testing.toy_model', 'named_toy'], "
        'allow_failed_imports=False)\n'
        "test_dataloader = dict(dataset=dict(type='NamedToyOccupancyDataset'"
        '))\n')
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(
        filter(None, [str(tmp_path), ROOT, env.get('PYTHONPATH')]))
    work_dir = str(tmp_path / 'work')
    proc = subprocess.run(
        [sys.executable, osp.join(ROOT, 'tools', 'test.py'), str(config),
         str(tmp_path / 'toy.pth'), '--work-dir', work_dir, '--show-dir',
         'show', '--cfg-options',
         'default_hooks.visualization.view_size=[60,80]'],
        cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    pictures = sorted(glob.glob(osp.join(work_dir, '*', 'show', '*.png')))
    assert [osp.basename(p) for p in pictures] == [
        'scene-0001_token0.png', 'scene-0001_token2.png', 'token1.png',
        'token3.png']
    widths = {_png_size(p)[0] for p in pictures}
    assert len(widths) == 1


def test_saved_labels_say_their_convention(tmp_path, capsys):
    """A grid holding Occ3D's free label 17, saved without a convention,
    ends the tool in one line naming --convention (before: a traceback
    from the renderer, 'labels [17] are outside [0, 17)'); with --config
    of an Occ3D config it draws; --save-pred writes the convention and
    class names, so that its file draws with no flag at all."""
    tool = load_tool('tools/misc/visualize_occ.py')
    grid = np.full((4, 4, 2), 17, dtype=np.int64)
    grid[0, 0, 0] = 4  # a car
    old = str(tmp_path / 'old.npz')
    np.savez_compressed(old, pred_occ=grid)
    fast = ['--view-size', '40', '60']
    with pytest.raises(SystemExit) as end:
        tool.main(['--pred', old, '--out', str(tmp_path / 'a.png')] + fast)
    assert end.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert 'pred_occ holds labels [17], outside the 17 classes' in err
    assert '--convention occ3d' in err
    occ3d = osp.join(ROOT, 'configs', 'sdg_occ',
                     'sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py')
    saved = str(tmp_path / 'saved.npz')
    tool.main(['--pred', old, '--config', occ3d, '--out',
               str(tmp_path / 'b.png'), '--save-pred', saved] + fast)
    assert osp.isfile(tmp_path / 'b.png')
    with np.load(saved, allow_pickle=False) as data:
        assert str(data['convention']) == 'occ3d'
        assert len(data['class_names']) == 18
        assert str(data['class_names'][17]) == 'free'
    tool.main(['--pred', saved, '--out', str(tmp_path / 'c.png')] + fast)
    assert osp.isfile(tmp_path / 'c.png')
