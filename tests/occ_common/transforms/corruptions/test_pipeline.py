"""Where OccCorruption goes in a config's pipeline, and the corrupted test
set of a config."""
import numpy as np
import pytest
from mmengine.config import Config

from projects.occ_common.apis import (build_corrupted_dataset,
                                      corrupted_dataset_cfg)
from projects.occ_common.testing.tool_logs import REPO_ROOT
from projects.occ_common.transforms.corruptions import with_corruption

TINY = f'{REPO_ROOT}/configs/occ_cyl/' \
    'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py'


def _types(pipeline):
    return [t['type'] for t in pipeline]


def test_goes_after_the_last_loader():
    """In the test pipeline: after the images, before their augmentation;
    the given pipeline is not changed."""
    pipeline = Config.fromfile(TINY).test_dataloader.dataset.pipeline
    before = _types(pipeline)
    out = with_corruption(pipeline, 'fog', 2, seed=3)
    i = before.index('LoadMultiViewImagesOcc') + 1
    assert _types(out) == before[:i] + ['OccCorruption'] + before[i:]
    assert out[i] == dict(type='OccCorruption', condition='fog',
                          severity=2, seed=3)
    assert _types(pipeline) == before


def test_beam_reduction_keeps_the_rings():
    pipeline = Config.fromfile(TINY).test_dataloader.dataset.pipeline
    sweeps = [t for t in with_corruption(pipeline, 'beam_reduction', 1)
              if t['type'] == 'LoadOccPointsFromMultiSweeps']
    assert sweeps and all(t['record_ring'] for t in sweeps)
    assert all('record_ring' not in t
               for t in with_corruption(pipeline, 'fog', 1))


def test_refusals():
    with pytest.raises(ValueError, match='unknown corruption'):
        with_corruption([dict(type='LoadMultiViewImagesOcc')], 'hail', 1)
    with pytest.raises(ValueError, match='loads no inputs'):
        with_corruption([dict(type='PackOccInputs')], 'fog', 1)
    with pytest.raises(ValueError, match='every must be >= 1'):
        corrupted_dataset_cfg(dict(pipeline=[]), every=0)


def test_dataset_cfg_inside_a_wrapper():
    """The innermost dataset gets the corruption, the previous frame
    where the condition needs it, and every n-th sample."""
    inner = dict(type='NuScenesOccDataset', load_interval=2,
                 pipeline=[dict(type='LoadMultiViewImagesOcc')])
    out = corrupted_dataset_cfg(dict(type='Wrapper', dataset=inner),
                                'frame_lost', 4, every=3)
    assert out['dataset']['load_interval'] == 6
    assert out['dataset']['num_frames'] == 2
    assert _types(out['dataset']['pipeline'])[-1] == 'OccCorruption'
    assert 'num_frames' not in inner and inner['load_interval'] == 2


def test_corrupted_test_set(converted_tiny_world):
    """The tiny world's test set without LiDAR: every sample packs zero
    points, the clean one its cloud."""
    cfg = Config.fromfile(TINY)
    cfg.test_dataloader.dataset.data_root = converted_tiny_world
    clean = build_corrupted_dataset(cfg)
    dark = build_corrupted_dataset(cfg, 'lidar_missing', 5)
    assert len(clean) == len(dark) == 2
    assert len(clean[0]['inputs']['points']) > 1000
    assert len(dark[0]['inputs']['points']) == 0
    assert len(build_corrupted_dataset(cfg, every=2)) == 1
    np.testing.assert_array_equal(clean[1]['inputs']['img'],
                                  dark[1]['inputs']['img'])
