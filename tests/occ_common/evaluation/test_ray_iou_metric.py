"""Tests of RayIoUMetric (OccRayIoUMetric) on tiny hand-made batches."""
import math
import os
import pickle
from unittest import mock

import numpy as np
import pytest
from mmdet3d.registry import METRICS
from mmengine.evaluator import Evaluator

from projects.occ_common.datasets.info_format import (INFO_VERSION,
                                                      REQUIRED_SAMPLE_KEYS)
from projects.occ_common.datasets.nuscenes_classes import OCC3D_CLASS_NAMES
from projects.occ_common.evaluation import (OccupancyMetric, RayIoUMetric,
                                            scene_ray_origins)

FREE = 17
CAR = OCC3D_CLASS_NAMES.index('car')
TRUCK = OCC3D_CLASS_NAMES.index('truck')
RAYS = 39 * 360
# A 1.2 m cube of 3 x 3 x 3 voxels of 0.4 m; an origin at its centre sits
# in voxel (1, 1, 1), so every ray's first occupied voxel is its own when
# the grid is full.
TINY = dict(pc_range=(0, 0, 0, 1.2, 1.2, 1.2), voxel_size=0.4)
CENTRE = [[0.6, 0.6, 0.6]]
CAST = 'projects.occ_common.evaluation.ray_iou_metric.cast_rays'


def _full(label):
    return np.full((3, 3, 3), label, dtype=np.uint8)


def _sample(pred, gt=CAR, token='t0', origins=CENTRE):
    sample = dict(token=token, pred_occ=_full(pred), gt_occ=_full(gt))
    if origins is not None:
        sample['ray_origins'] = np.asarray(origins, np.float32)
    return sample


def test_metric_pools_the_ray_counts_of_a_batch():
    """GT all car, origin inside; all 14,040 rays hit car in the GT.
    Sample A predicts car everywhere: TP = GT = pred = N. Sample B
    predicts truck everywhere: car GT N, truck pred N, no TP. Pooled:
    car TP N, GT 2N, pred N -> N / 2N = 50 %; truck 0 /
    (0 + N - 0) = 0 %; RayIoU = (50 + 0) / 2 = 25 % at every threshold
    (the mean of the per-sample RayIoUs, (100 + 0) / 2, would be 50 %)."""
    metric = METRICS.build(dict(type='OccRayIoUMetric', **TINY))
    assert isinstance(metric, RayIoUMetric)
    metric.process({}, [_sample(CAR, token='a'), _sample(TRUCK, token='b')])
    first = metric.results[0]
    assert first['gt'][CAR] == first['pred'][CAR] == RAYS
    assert first['tp'][:, CAR].tolist() == [RAYS] * 3
    # Results are counts, small enough to gather across ranks cheaply.
    assert len(pickle.dumps(first)) < 2000
    with mock.patch('projects.occ_common.evaluation.ray_iou_metric.'
                    'print_log') as log:
        metrics = metric.compute_metrics(metric.results)
    for key in ('RayIoU', 'RayIoU@1', 'RayIoU@2', 'RayIoU@4'):
        assert metrics[key] == 25, key
    assert metrics['RayIoU/car'] == 50 and metrics['RayIoU@4/truck'] == 0
    assert 'RayIoU (%) of 2 samples' in log.call_args[0][0]


def _info_file(path):
    """Two frames of one scene: egos at the global origin (t = 0) and at
    x = 0.2 m (t = 1), both LiDARs at (0.6, 0.6, 0.6) in their ego."""
    lidar2ego = np.eye(4)
    lidar2ego[:3, 3] = 0.6
    entries = []
    for i, x in enumerate((0.0, 0.2)):
        ego2global = np.eye(4)
        ego2global[0, 3] = x
        entry = {key: None for key in REQUIRED_SAMPLE_KEYS}
        entry.update(sample_idx=i, token=f't{i}', timestamp=float(i),
                     scene_token='s', scene_name='scene-0001',
                     ego2global=ego2global.tolist(),
                     lidar_points=dict(lidar2ego=lidar2ego.tolist()))
        entries.append(entry)
    with open(path, 'wb') as f:
        pickle.dump(dict(metainfo=dict(info_version=INFO_VERSION),
                         data_list=entries), f)
    return entries


def test_metric_reads_the_origins_of_the_info_file(tmp_path):
    """Sample t0's origins are its own LiDAR (0.6, 0.6, 0.6) and that of
    t1, (0.8, 0.6, 0.6): both in the full car grid, so the GT counts
    2 x 14,040 = 28,080 car rays, as with the origins packed."""
    entries = _info_file(tmp_path / 'infos.pkl')
    metric = RayIoUMetric(ann_file='infos.pkl', data_root=str(tmp_path),
                          **TINY)
    metric.process({}, [_sample(CAR, token='t0', origins=None)])
    assert metric.results[0]['gt'][CAR] == 2 * RAYS
    packed = RayIoUMetric(**TINY)
    origins = scene_ray_origins(entries)['t0']
    assert np.allclose(origins, [[0.6, 0.6, 0.6], [0.8, 0.6, 0.6]])
    packed.process({}, [_sample(CAR, token='t0', origins=origins)])
    for key in ('gt', 'pred', 'tp'):
        assert np.array_equal(metric.results[0][key],
                              packed.results[0][key])
    with pytest.raises(ValueError, match='not in infos.pkl'):
        metric.process({}, [_sample(CAR, token='elsewhere', origins=None)])


@pytest.mark.parametrize('on_disk', [False, True])
def test_metric_casts_the_gt_once_when_caching(tmp_path, on_disk):
    """The second evaluation of a sample casts the prediction alone; a
    changed GT is cast again (the cache is keyed by content); on disk the
    hits survive into a new metric."""
    options = dict(gt_cache_dir=str(tmp_path)) if on_disk else dict(
        cache_gt_rays=True)
    metric = RayIoUMetric(**options, **TINY)
    with mock.patch(CAST, wraps=metric._cast.__globals__['cast_rays']) as c:
        for gt in (CAR, CAR, TRUCK):
            metric.process({}, [_sample(CAR, gt=gt)])
        assert [len(call.args[0]) for call in c.call_args_list] == [2, 1, 2]
    assert metric.results[0]['tp'][:, CAR].tolist() == [RAYS] * 3
    for key in ('gt', 'pred', 'tp'):
        assert np.array_equal(metric.results[0][key], metric.results[1][key])
    if on_disk:
        assert len(list(tmp_path.glob('*.npz'))) == 2
        again = RayIoUMetric(**options, **TINY)
        with mock.patch(CAST, wraps=metric._cast.__globals__['cast_rays']) \
                as c:
            again.process({}, [_sample(CAR)])
        assert len(c.call_args.args[0]) == 1
        assert np.array_equal(again.results[0]['tp'],
                              metric.results[0]['tp'])


def test_metric_beside_occupancy_metric_in_one_evaluator():
    """Both metrics under the 'occ' prefix, with no key in common."""
    evaluator = Evaluator([
        OccupancyMetric(convention='occ3d', use_camera_mask=False),
        METRICS.build(dict(type='OccRayIoUMetric', **TINY)),
    ])
    evaluator.process([_sample(CAR)])
    with mock.patch('projects.occ_common.evaluation.ray_iou_metric.'
                    'print_log'), mock.patch(
                        'projects.occ_common.evaluation.occupancy_metric.'
                        'print_log'):
        metrics = evaluator.evaluate(1)
    assert metrics['occ/mIoU'] == 100 and metrics['occ/RayIoU'] == 100


def test_metric_refuses_masked_labels_and_missing_origins():
    metric = RayIoUMetric(**TINY)
    with pytest.raises(ValueError, match='mask_with'):
        metric.process({}, [_sample(CAR, gt=255)])
    with pytest.raises(ValueError, match=r'shape \(3, 3, 3\)'):
        flat = dict(_sample(CAR), pred_occ=np.zeros((2, 2), int))
        metric.process({}, [flat])
    with pytest.raises(ValueError, match='ann_file'):
        metric.process({}, [_sample(CAR, origins=None)])


def test_metric_of_no_samples_is_nan():
    with mock.patch('projects.occ_common.evaluation.ray_iou_metric.'
                    'print_log'):
        metrics = RayIoUMetric(**TINY).compute_metrics([])
    assert math.isnan(metrics['RayIoU']) and math.isnan(metrics['RayIoU@2'])


def test_origins_of_another_dataset_are_refused(tmp_path):
    """The metric reads t0's origins from its own info file; a sample of
    the evaluated dataset with the same token but another ego pose or
    time (the dataloader's data_root overridden, the metric's not) is
    refused naming the file (before: scored with these origins). The
    sample of the file itself passes."""
    entries = _info_file(tmp_path / 'infos.pkl')
    metric = RayIoUMetric(ann_file='infos.pkl', data_root=str(tmp_path),
                          **TINY)
    own = _sample(CAR, token='t0', origins=None)
    own.update(timestamp=0.0, ego2global=np.asarray(
        entries[0]['ego2global'], np.float32))
    metric.process({}, [own])
    moved = dict(own, ego2global=np.eye(4, dtype=np.float32) * 1.0)
    moved['ego2global'][1, 3] = 5.0
    with pytest.raises(ValueError, match=r'sample t0 is not the sample of '
                       r'token t0 in .*infos\.pkl \(ego2global differ\): '
                       "the metric would cast rays from another dataset's"):
        metric.process({}, [moved])
    with pytest.raises(ValueError, match=r'\(timestamp 7.0 vs 0.0 differ\)'):
        metric.process({}, [dict(own, timestamp=7.0)])


@pytest.mark.parametrize('damage', ['another sample', 'garbage'])
def test_replaced_cache_file_is_cast_again(tmp_path, damage):
    """The cache file of sample A replaced by that of sample B (same
    origins, GT truck: another key's file) or by bytes that are no .npz:
    the GT is cast again with a warning naming the file, and the counts
    are A's (before: B's hits were read as A's; a damaged file gave
    NaN)."""
    cache = tmp_path / 'cache'
    metric = RayIoUMetric(gt_cache_dir=str(cache), **TINY)
    metric.process({}, [_sample(CAR, gt=CAR, token='a')])
    metric.process({}, [_sample(CAR, gt=TRUCK, token='b')])
    file_a, file_b = sorted(cache.glob('*.npz'), key=os.path.getmtime)
    if damage == 'garbage':
        file_a.write_bytes(b'not an npz')
    else:
        file_a.write_bytes(file_b.read_bytes())
    again = RayIoUMetric(gt_cache_dir=str(cache), **TINY)
    with mock.patch('projects.occ_common.evaluation.ray_iou_metric.'
                    'print_log') as log, mock.patch(
                        CAST, wraps=metric._cast.__globals__['cast_rays']) \
            as cast:
        again.process({}, [_sample(CAR, gt=CAR, token='a')])
    assert f'ignoring the cache file {file_a}' in log.call_args[0][0]
    assert len(cast.call_args.args[0]) == 2  # prediction and GT
    for key in ('gt', 'pred', 'tp'):
        assert np.array_equal(again.results[0][key], metric.results[0][key])
