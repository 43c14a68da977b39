"""Info files: read without running code, checked key by key, never empty.

Each test damages a private copy of the converted tiny world (one scene,
two key frames) and builds the SurroundOcc dataset of the base config.
"""
import os
import os.path as osp
import re

import mmengine
import numpy as np
import pytest
from mmdet3d.registry import DATASETS
from mmdet3d.utils import register_all_modules
from mmengine.config import Config

import projects.occ_common  # noqa: F401  (registers)
from projects.occ_common.datasets.converters.nuscenes_occ_converter import \
    SYNTHETIC_MARKER
from projects.occ_common.fileio import (CorruptFileError, RefusedGlobalError,
                                        load_info_file)
from projects.occ_common.testing.tiny_world import make_tiny_world
from projects.occ_common.testing.tool_logs import run_create_data

register_all_modules(init_default_scope=True)
REPO = osp.dirname(osp.dirname(osp.dirname(osp.dirname(__file__))))
TRAIN = 'nuscenes_occ_infos_train.pkl'


def build(root, test_mode=False, split='train'):
    cfg = Config.fromfile(
        osp.join(REPO, 'configs', '_base_', 'datasets', 'surroundocc-nus.py'))
    ds_cfg = cfg.train_dataloader.dataset
    ds_cfg.data_root = root
    ds_cfg.ann_file = f'nuscenes_occ_infos_{split}.pkl'
    ds_cfg.test_mode = test_mode
    return DATASETS.build(ds_cfg)


def rewrite(root, edit):
    """Apply ``edit(infos)`` to the train info file."""
    path = osp.join(root, TRAIN)
    infos = load_info_file(path)
    edit(infos)
    mmengine.dump(infos, path)
    return infos


class _Evil:

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.system, (f'touch {self.marker}', ))


def test_info_file_with_a_payload_is_never_run(world_copy, tmp_path):
    """The os.system payload that used to run through tools/test.py."""
    marker = tmp_path / 'pwned'
    path = osp.join(world_copy, TRAIN)
    mmengine.dump(dict(metainfo={}, data_list=[_Evil(marker)]), path)
    with pytest.raises(RefusedGlobalError,
                       match=f'Refusing to load info file {re.escape(path)}'
                       ': it pickles posix.system'):
        build(world_copy)
    assert not marker.exists()


@pytest.mark.parametrize('size', [0, 300])
def test_empty_or_truncated_info_file_names_it(world_copy, size):
    path = osp.join(world_copy, TRAIN)
    with open(path, 'rb') as f:
        data = f.read()
    with open(path, 'wb') as f:
        f.write(data[:size])
    with pytest.raises(CorruptFileError, match=re.escape(path)):
        build(world_copy)


@pytest.mark.parametrize('edit, msg', [
    (lambda s: s['images']['CAM_BACK'].pop('cam2img'),
     r"images: CAM_BACK lacks the keys \['cam2img'\]"),
    (lambda s: s['lidar_points'].update(lidar2ego=np.eye(3).tolist()),
     r'lidar_points.lidar2ego: expected a 4x4 matrix, got shape \(3, 3\)'),
    (lambda s: s['images']['CAM_FRONT']['lidar2cam'][0].__setitem__(
        0, float('nan')),
     'images.CAM_FRONT.lidar2cam: the matrix holds NaN or inf'),
    (lambda s: s['images']['CAM_FRONT']['cam2img'][1].__setitem__(
        2, float('inf')),
     'images.CAM_FRONT.cam2img: the matrix holds NaN or inf'),
    (lambda s: s['lidar_sweeps'][0]['lidar_points'].pop('sensor2lidar') and
     s['lidar_sweeps'][0]['lidar_points'].pop('lidar2sensor'),
     r'lidar_sweeps\[0\]: lidar_points needs sensor2lidar or lidar2sensor'),
    (lambda s: s.pop('lidar_points'), r"lacks the keys \['lidar_points'\]"),
    (lambda s: s['lidar_sweeps'][0].update(timestamp='1532402927.5'),
     r"lidar_sweeps\[0\].timestamp: expected a number of seconds, got str"),
])
def test_malformed_sample_names_file_sample_and_key(world_copy, edit, msg):
    """A missing nested key (KeyError 'cam2img'), a 3x3 lidar2ego
    (IndexError), NaN / inf calibration (later a crash inside BCE), a
    string timestamp (later a TypeError in the sweep merge)."""
    infos = rewrite(world_copy, lambda i: edit(i['data_list'][1]))
    token = infos['data_list'][1]['token']
    with pytest.raises(ValueError,
                       match=f'{TRAIN}: sample {token} .*{msg}'):
        build(world_copy)


def test_empty_dataset_is_an_error(world_copy):
    """0 samples in the file, or none left by filter_empty_gt."""
    infos = rewrite(world_copy,
                    lambda i: [s.update(occ_surroundocc_path=None)
                               for s in i['data_list']])
    with pytest.raises(ValueError, match='none of its 2 samples .* has a '
                       'surroundocc occupancy label'):
        build(world_copy)
    assert len(build(world_copy, test_mode=True)) == 2
    infos['data_list'] = []
    mmengine.dump(infos, osp.join(world_copy, TRAIN))
    with pytest.raises(ValueError, match=f'{TRAIN} holds no samples'):
        build(world_copy, test_mode=True)


def test_info_records_the_calibrated_image_size(converted_tiny_world):
    infos = load_info_file(osp.join(converted_tiny_world, TRAIN))
    image = infos['data_list'][0]['images']['CAM_FRONT']
    assert (image['width'], image['height']) == (160, 90)


def test_scenes_outside_the_official_split_are_an_error(world_copy):
    """Without the synthetic marker the official v1.0-mini split applies,
    which lists none of the world's scenes: an error, not a 0-sample pkl
    written with exit code 0."""
    os.remove(osp.join(world_copy, SYNTHETIC_MARKER))
    with pytest.raises(ValueError,
                       match=r'the train and val split would hold no sample'
                       r".*scenes \['scene-0001'\]"):
        run_create_data('--root-path', world_copy, '--version', 'v1.0-mini',
                        '--overwrite')
    with pytest.raises(FileNotFoundError,
                       match=r"v1.0-trainval not found: .* holds the nuScenes "
                       r"versions \['v1.0-mini'\]"):
        run_create_data('--root-path', world_copy, '--overwrite')


def test_v1_0_test_of_a_synthetic_world(tmp_path):
    """All scenes of a synthetic v1.0-test world form the test split
    (KeyError 'train' before)."""
    root = make_tiny_world(str(tmp_path / 'world'), version='v1.0-test')
    written = run_create_data('--root-path', root, '--version', 'v1.0-test')
    assert list(written) == ['test']
    assert len(build(root, test_mode=True, split='test')) == 2


def _duplicate_first(infos):
    infos['data_list'].append(dict(infos['data_list'][0]))


@pytest.mark.parametrize('edit, msg', [
    (_duplicate_first,
     r'sample (\w+) appears twice in data_list \(at 0 and 2\): it would be '
     'trained on and evaluated twice'),
    (lambda i: i['data_list'].insert(1, ['not', 'a', 'dict']),
     r"sample 1 of data_list is a list \(\['not', 'a', 'dict'\]\), not a "
     'dict'),
    (lambda i: i.update(metainfo=[('info_version', 'occ-nus-1.0')]),
     'metainfo must be a dict .* got list'),
])
def test_unclear_or_silent_info_files_name_file_and_sample(
        world_copy, edit, msg):
    """A sample listed twice (before: loaded twice, without a word), an
    entry that is not a dict and a metainfo list (before, both:
    AttributeError "'list' object has no attribute 'get'")."""
    rewrite(world_copy, edit)
    with pytest.raises(ValueError, match=f'{TRAIN}: {msg}'):
        build(world_copy, test_mode=True)


def test_metainfo_argument_must_be_a_dict(world_copy):
    """metainfo=[...] in a dataset config: a TypeError naming the info
    file (before: mmengine's "dictionary update sequence element #0 has
    length 7; 2 is required")."""
    cfg = Config.fromfile(
        osp.join(REPO, 'configs', '_base_', 'datasets', 'surroundocc-nus.py'))
    ds_cfg = cfg.train_dataloader.dataset
    ds_cfg.update(data_root=world_copy, metainfo=['classes'])
    with pytest.raises(TypeError, match=f'{TRAIN}: metainfo must be a dict'):
        DATASETS.build(ds_cfg)


def _sweep(i):
    return i['data_list'][1]['lidar_sweeps'][0]


@pytest.mark.parametrize('edit, msg', [
    (lambda i: i['data_list'][1].update(timestamp=float('nan')),
     'timestamp: expected a finite number of seconds, got nan'),
    (lambda i: _sweep(i).update(timestamp=i['data_list'][1]['timestamp'] +
                                0.05),
     r'lidar_sweeps\[0\]: the sweep is time-stamped 0.050 s after its key '
     'frame'),
    (lambda i: _sweep(i)['lidar_points'].update(
        sensor2lidar=np.zeros((4, 4)).tolist()),
     r'lidar_sweeps\[0\].lidar_points.sensor2lidar: expected a rigid '
     'transform'),
    (lambda i: i['data_list'][1]['images']['CAM_BACK'].update(
        cam2ego=(2 * np.eye(4)).tolist()),
     'images.CAM_BACK.cam2ego: expected a rigid transform'),
])
def test_times_and_transforms_are_checked(world_copy, edit, msg):
    """A NaN timestamp (NaN time lags), a sweep after its key frame (a
    negative time lag), an all-zero sensor2lidar (every sweep point at the
    origin), a scaled cam2ego: each was accepted without a word."""
    infos = rewrite(world_copy, edit)
    token = infos['data_list'][1]['token']
    with pytest.raises(ValueError, match=f'{TRAIN}: sample {token} .*{msg}'):
        build(world_copy)


@pytest.mark.parametrize('shift, msg', [
    (+0.6, 'the previous key frame is time-stamped -0.1.. s before'),
    (-2.0, 'the previous key frame is time-stamped 2.5.. s before'),
])
def test_previous_key_frame_lies_in_the_past_within_two_seconds(
        world_copy, shift, msg):
    """Key frame 1's link to key frame 0, 0.5 s before it, moved 0.6 s
    later (0.1 s in the future: a temporal model fused the next frame as
    the last one) or 2 s earlier (2.5 s: no consecutive key frame)."""
    def edit(infos):
        link = infos['data_list'][1]['prev_key_frame']
        link['timestamp'] += shift

    infos = rewrite(world_copy, edit)
    token = infos['data_list'][1]['token']
    cfg = Config.fromfile(
        osp.join(REPO, 'configs', '_base_', 'datasets', 'surroundocc-nus.py'))
    ds_cfg = cfg.train_dataloader.dataset
    ds_cfg.update(data_root=world_copy, ann_file=TRAIN, num_frames=2)
    with pytest.raises(ValueError, match=f'{TRAIN}: sample {token} frame '
                       f't-1: {msg}'):
        DATASETS.build(ds_cfg)
    # The converter's link: key frame 0's own timestamp.
    rewrite(world_copy, lambda i: i['data_list'][1]['prev_key_frame'].update(
        timestamp=i['data_list'][0]['timestamp']))
    assert len(DATASETS.build(ds_cfg)) == 2
