"""The real nuScenes key frame of ``../shared`` through every condition at
its highest severity: real images (1600 x 900), a real 32-beam cloud with
its ring column, real calibration. The sample has no sweeps and no
previous key frame, which two conditions need: there they leave it as it
is, and say so."""
import copy
import os.path as osp

import numpy as np
import pytest

from projects.occ_common.analysis.real_sample import (MISSING_REASON,
                                                      real_info_file,
                                                      real_sample_dir)
from projects.occ_common.testing.corruption_samples import loaded_sample
from projects.occ_common.testing.tool_logs import run_create_data
from projects.occ_common.transforms.corruptions import (CONDITIONS,
                                                        OccCorruption)
from projects.occ_common.transforms.corruptions.lidar import points_array

pytestmark = [
    pytest.mark.skipif(real_sample_dir() is None, reason=MISSING_REASON),
    pytest.mark.filterwarnings('ignore:.*label folder .* not found'),
    pytest.mark.filterwarnings('ignore:.*scene unknown'),
]


@pytest.fixture(scope='module')
def real(tmp_path_factory):
    """The sample after the loaders (ego returns removed)."""
    out = str(tmp_path_factory.mktemp('real_info'))
    info = run_create_data('--root-path', real_sample_dir(), '--out-dir',
                           out, '--from-mmdet3d-info', real_info_file())
    return loaded_sample(real_sample_dir(), 0,
                         ann_file=next(iter(info.values())))


def _ranges(results):
    return np.linalg.norm(points_array(results)[:, :3], axis=1)


#: The camera conditions that change whole views; the pixel corruptions of
#: six 1600 x 900 views take seconds each (shot noise draws 26 million
#: Poisson counts): the slow tier's.
_VIEWS = {'camera_crash', 'camera_blackout', 'frame_lost', 'missing_views'}


@pytest.mark.parametrize('condition', [
    pytest.param(c, marks=pytest.mark.slow)
    if CONDITIONS[c].family == 'camera' and c not in _VIEWS else c
    for c in CONDITIONS
])
def test_real_sample_at_severity_5(real, condition):
    out = OccCorruption(condition, 5)(copy.deepcopy(real))
    points, clean = points_array(out), points_array(real)
    same_images = all(np.array_equal(a, b)
                      for a, b in zip(out['img'], real['img']))
    family = CONDITIONS[condition].family
    if condition in ('camera_crash', 'camera_blackout'):
        black = sum(not img.any() for img in out['img'])
        assert black == (5 if condition == 'camera_crash' else 6)
    elif condition == 'missing_views':
        assert len(out['img']) == len(out['lidar2img']) == 1
    elif condition == 'frame_lost':
        # No previous key frame: the frame is its own (a scene's start).
        assert same_images
    elif family == 'camera':
        assert not same_images
        assert out['img'][0].shape == (900, 1600, 3)
    else:
        assert same_images
    if condition == 'beam_reduction':
        # The real file's ring column: 4 of the 32 beams, every 8th.
        ring = real['points_ring']
        assert set(np.unique(ring)) <= set(range(32))
        np.testing.assert_array_equal(points, clean[ring % 8 == 0])
    elif condition == 'point_reduction':
        assert len(points) == len(clean) - round(0.9 * len(clean))
    elif condition == 'lidar_fog':
        # exp(-2 * 0.06 * r): the far returns go first.
        assert 0 < len(points) < 0.6 * len(clean)
        assert _ranges(out).mean() < _ranges(real).mean()
    elif condition == 'lidar_crosstalk':
        moved = (points[:, :3] != clean[:, :3]).any(1).sum()
        assert moved == round(0.02 * len(clean))
    elif condition == 'lidar_missing':
        assert len(points) == 0
    elif condition == 'temporal_misalignment':
        # No sweeps: no late data to hand over.
        assert out['corruption_delay_s'] == 0.0
        np.testing.assert_array_equal(points, clean)
    elif condition == 'spatial_misalignment':
        offsets = out['lidar2cam'] @ np.linalg.inv(real['lidar2cam'])
        shifts = np.linalg.norm(offsets[:, :3, 3], axis=1)
        np.testing.assert_allclose(shifts, 0.35)
    elif family == 'camera':
        np.testing.assert_array_equal(points, clean)
    assert osp.basename(out['img_path'][0]).endswith('.jpg')
