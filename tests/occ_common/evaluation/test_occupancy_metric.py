"""Tests of OccupancyMetric on hand-computed confusion matrices."""
import math
import pickle
from itertools import chain, zip_longest
from unittest import mock

import numpy as np
import pytest
import torch

from projects.occ_common.evaluation import (OCC3D_CLASSES, SURROUNDOCC_CLASSES,
                                            OccupancyMetric,
                                            read_confusion_csv)

SURROUND4 = ('empty', 'a', 'b', 'c')
OCC3D4 = ('others', 'a', 'b', 'free')


def _sample(gt, pred, idx='s0', grid=(2, 2, 2), mask=None, **flags):
    """A data sample dict; flat label lists are reshaped to ``grid``."""
    sample = dict(
        sample_idx=idx,
        gt_occ=torch.tensor(gt).reshape(grid),
        pred_occ=np.asarray(pred).reshape(grid),
        **flags)
    if mask is not None:
        sample['mask_camera'] = np.asarray(mask, dtype=bool).reshape(grid)
    return sample


def _run(metric, samples):
    """process every sample, then compute_metrics (table log captured)."""
    metric.process({}, samples)
    with mock.patch('projects.occ_common.evaluation.occupancy_metric.'
                    'print_log') as log:
        metrics = metric.compute_metrics(metric.results)
    return metrics, log.call_args[0][0]


def test_surroundocc_hand_computed():
    """8 voxels, classes (empty, a, b, c); voxel 5 is ignored (GT 255).

    gt   0 0 1 1 2 255 0 1
    pred 0 1 1 1 0   3 0 2
    counted (GT row, pred col): (0,0) x2, (0,1), (1,1) x2, (2,0), (1,2)
    a: TP 2, GT 3, pred 3 -> 2 / 4 = 50 %
    b: TP 0, GT 1, pred 1 -> 0 / 2 = 0 %
    c: never occurs once voxel 5 is ignored -> NaN, not in the mean
    mIoU = (50 + 0) / 2 = 25 %
    IoU: occupied GT {2,3,4,7}, pred {1,2,3,7}, both {2,3,7}
         3 / (4 + 4 - 3) = 60 %
    empty: TP 2, GT 3, pred 3 -> 50 %
    """
    metric = OccupancyMetric(class_names=SURROUND4)
    metrics, table = _run(metric, [
        _sample([0, 0, 1, 1, 2, 255, 0, 1], [0, 1, 1, 1, 0, 3, 0, 2])
    ])
    expected_confusion = np.array([[2, 1, 0, 0], [0, 2, 1, 0],
                                   [1, 0, 0, 0], [0, 0, 0, 0]])
    assert np.array_equal(metric.results[0]['confusion'], expected_confusion)
    assert metrics['mIoU'] == pytest.approx(25.0)
    assert metrics['IoU'] == pytest.approx(60.0)
    assert metrics['a'] == pytest.approx(50.0)
    assert metrics['b'] == pytest.approx(0.0)
    assert math.isnan(metrics['c'])
    assert metrics['empty'] == pytest.approx(50.0)
    assert 'mIoU' in table and 'empty *' in table


def test_occ3d_camera_mask_hand_computed():
    """Classes (others, a, b, free=3); voxel 7 is outside the camera mask.

    gt   3 3 0 1 1 3 0 3
    pred 3 1 0 1 3 3 3 2
    mask 1 1 1 1 1 1 1 0
    others: TP 1 (v2), GT 2 (v2, v6), pred 1 -> 1 / 2 = 50 %
    a:      TP 1 (v3), GT 2 (v3, v4), pred 2 (v1, v3) -> 1 / 3 = 33.33 %
            (v1 free -> a is a false positive, v4 a -> free a false neg.)
    b:      only predicted at the masked v7 -> never occurs -> NaN
    mIoU = (50 + 33.33) / 2 = 41.67 %
    IoU: non-free GT {2,3,4,6}, pred {1,2,3}, both {2,3} -> 2 / 5 = 40 %
    Without the mask v7 counts: b = 0 / 1 = 0 %, mIoU = 83.33 / 3
    = 27.78 %, IoU = 2 / (4 + 4 - 2) = 33.33 %.
    """
    gt = [3, 3, 0, 1, 1, 3, 0, 3]
    pred = [3, 1, 0, 1, 3, 3, 3, 2]
    mask = [1, 1, 1, 1, 1, 1, 1, 0]
    masked, _ = _run(
        OccupancyMetric(convention='occ3d', class_names=OCC3D4),
        [_sample(gt, pred, mask=mask)])
    assert masked['others'] == pytest.approx(50.0)
    assert masked['a'] == pytest.approx(100 / 3)
    assert math.isnan(masked['b'])
    assert masked['mIoU'] == pytest.approx(125 / 3)
    assert masked['IoU'] == pytest.approx(40.0)
    unmasked, _ = _run(
        OccupancyMetric(
            convention='occ3d', class_names=OCC3D4, use_camera_mask=False),
        [_sample(gt, pred, mask=mask)])
    assert unmasked['b'] == pytest.approx(0.0)
    assert unmasked['mIoU'] == pytest.approx(250 / 9)
    assert unmasked['IoU'] == pytest.approx(100 / 3)


def test_class_voxel_counts_after_ignore_and_camera_mask():
    """The Occ3D sample above with class_voxel_counts: GT rows after the
    mask (v7, a free voxel, is not counted): others v2, v6 -> 2; a v3, v4
    -> 2; b none -> 0; free v0, v1, v5 -> 3. Off by default."""
    gt = [3, 3, 0, 1, 1, 3, 0, 3]
    pred = [3, 1, 0, 1, 3, 3, 3, 2]
    mask = [1, 1, 1, 1, 1, 1, 1, 0]
    metrics, table = _run(
        OccupancyMetric(convention='occ3d', class_names=OCC3D4,
                        class_voxel_counts=True),
        [_sample(gt, pred, mask=mask)])
    assert {k: v for k, v in metrics.items() if k.startswith('gt_')} == {
        'gt_voxels/others': 2, 'gt_voxels/a': 2, 'gt_voxels/b': 0,
        'gt_voxels/free': 3}
    assert 'GT voxels' in table
    assert table.splitlines()[3].split() == ['a', '33.33', '2']
    plain, table = _run(
        OccupancyMetric(convention='occ3d', class_names=OCC3D4),
        [_sample(gt, pred, mask=mask)])
    assert not any(k.startswith('gt_voxels') for k in plain)
    assert 'GT voxels' not in table


def _two_samples(**flags_b):
    """Classes (empty, a, b), 4 voxels each.

    A: gt 1 1 1 1, pred 1 1 1 1 -> per-sample mIoU 100 % (b absent)
    B: gt 2 0 0 0, pred 1 0 0 0 -> a 0 / 1, b 0 / 1 -> mIoU 0 %
    """
    return [
        _sample([1, 1, 1, 1], [1, 1, 1, 1], 'A', (4, 1, 1), is_rainy=True,
                is_night=False),
        _sample([2, 0, 0, 0], [1, 0, 0, 0], 'B', (4, 1, 1), **flags_b)
    ]


def test_dataset_accumulation_differs_from_sample_mean():
    """Mean of per-sample mIoUs = (100 + 0) / 2 = 50 %, but over the
    dataset a: TP 4, GT 4, pred 5 -> 80 %; b: TP 0, GT 1 -> 0 %;
    mIoU = 40 %. IoU: occupied GT 5, pred 5, both 5 -> 100 %."""
    metrics, _ = _run(
        OccupancyMetric(class_names=SURROUND4[:3]),
        _two_samples(is_rainy=True, is_night=True))
    assert metrics['mIoU'] == pytest.approx(40.0)
    assert metrics['a'] == pytest.approx(80.0)
    assert metrics['IoU'] == pytest.approx(100.0)


def test_ddp_gathering_equals_single_process():
    """Three samples on two ranks as DefaultSampler splits them (rank 0:
    0, 2; rank 1: 1, 0 padded); mmengine's collect_results interleaves
    the pickled parts and drops the padding. The result equals the
    single-process one, key for key."""
    samples = _two_samples(is_rainy=False, is_night=True) + [
        _sample([0, 2, 2, 0], [0, 2, 0, 0], 'C', (4, 1, 1), is_rainy=True,
                is_night=True)
    ]
    kwargs = dict(class_names=SURROUND4[:3], subsets=('rainy', 'night'))
    single, _ = _run(OccupancyMetric(**kwargs), samples)
    ranks = [OccupancyMetric(**kwargs), OccupancyMetric(**kwargs)]
    ranks[0].process({}, [samples[0], samples[2]])
    ranks[1].process({}, [samples[1], samples[0]])
    parts = [pickle.loads(pickle.dumps(r.results)) for r in ranks]
    gathered = [
        x for x in chain.from_iterable(zip_longest(*parts)) if x is not None
    ][:len(samples)]
    with mock.patch('projects.occ_common.evaluation.occupancy_metric.'
                    'print_log'):
        merged = ranks[0].compute_metrics(gathered)
    assert merged.keys() == single.keys()
    for key, value in single.items():
        assert merged[key] == pytest.approx(value, nan_ok=True), key
    assert set(parts[0][0]) == {'confusion', 'subsets'}
    assert parts[0][0]['confusion'].shape == (3, 3)


def test_subsets():
    """Rainy = A and B -> as the dataset: mIoU 40 %, IoU 100 %.
    Night = B only: a 0 / 1, b 0 / 1 -> mIoU 0 %; geometrically the
    one occupied voxel is predicted occupied -> IoU 100 %."""
    metrics, table = _run(
        OccupancyMetric(
            class_names=SURROUND4[:3], subsets=('rainy', 'night')),
        _two_samples(is_rainy=True, is_night=True))
    assert metrics['rainy/mIoU'] == pytest.approx(40.0)
    assert metrics['rainy/IoU'] == pytest.approx(100.0)
    assert metrics['night/mIoU'] == pytest.approx(0.0)
    assert metrics['night/IoU'] == pytest.approx(100.0)
    assert 'night' in table


def test_subset_without_samples_and_missing_flag():
    """No night sample gives NaN; a sample without its flag raises."""
    metrics, _ = _run(
        OccupancyMetric(class_names=SURROUND4[:3], subsets=('night', )),
        _two_samples(is_rainy=False, is_night=False))
    assert math.isnan(metrics['night/mIoU'])
    with pytest.raises(ValueError, match="sample B has no 'is_night'"):
        OccupancyMetric(subsets=('night', )).process({}, _two_samples())


def test_distance_ranges():
    """4 x 4 x 2 grid, 1 m voxels over [-2, 2]^2: column centres at
    +-0.5, +-1.5 m lie at 0.71 m (4 inner columns), 1.58 m (8 edge
    columns) or 2.12 m (4 corners). GT is class a everywhere; pred is a,
    except b on the edge columns at z = 0 and empty at the corners.

    0-1 m: 8 voxels correct -> a 100 %, mIoU 100 %, IoU 100 %
    1-2 m: 16 voxels, 8 predicted b -> a 8 / 16 = 50 %, b 0 / 8 = 0 %,
           mIoU 25 %; all occupied -> IoU 100 %
    2-3 m: 8 voxels predicted empty -> a 0 %, mIoU 0 %, IoU 0 %
    all:   a: TP 16, GT 32, pred 16 (8 inner + 8 edge at z = 1)
           -> 16 / (32 + 16 - 16) = 50 %, b 0 % -> mIoU 25 %;
           occupied pred 24, GT 32, both 24 -> IoU 24 / 32 = 75 %
    """
    gt = torch.ones(4, 4, 2, dtype=torch.long)
    pred = gt.clone()
    centre = torch.tensor([-1.5, -0.5, 0.5, 1.5])
    dist = torch.hypot(centre[:, None], centre[None, :])
    pred[(dist > 1) & (dist < 2), 0] = 2
    pred[dist > 2] = 0
    metric = OccupancyMetric(
        class_names=SURROUND4[:3],
        distance_ranges=[(0, 1), (1, 2), (2, 3)],
        voxel_size=(1.0, 1.0, 1.0),
        point_cloud_range=(-2.0, -2.0, -1.0, 2.0, 2.0, 1.0))
    metrics, _ = _run(metric, [dict(sample_idx=0, gt_occ=gt, pred_occ=pred)])
    assert metrics['dist_0-1m/mIoU'] == pytest.approx(100.0)
    assert metrics['dist_0-1m/IoU'] == pytest.approx(100.0)
    assert metrics['dist_1-2m/mIoU'] == pytest.approx(25.0)
    assert metrics['dist_1-2m/IoU'] == pytest.approx(100.0)
    assert metrics['dist_2-3m/mIoU'] == pytest.approx(0.0)
    assert metrics['dist_2-3m/IoU'] == pytest.approx(0.0)
    assert metrics['a'] == pytest.approx(50.0)
    assert metrics['mIoU'] == pytest.approx(25.0)
    assert metrics['IoU'] == pytest.approx(75.0)
    with pytest.raises(ValueError, match='sample 1: grid'):
        metric.process({}, [dict(sample_idx=1, gt_occ=gt[:2],
                                 pred_occ=pred[:2])])


def test_bad_samples_raise_naming_the_sample():
    """Shape mismatch, labels out of range (255 only allowed in GT),
    float labels, and a missing Occ3D camera mask."""
    metric = OccupancyMetric(class_names=SURROUND4)
    bad = [
        (dict(sample_idx='tok7', gt_occ=np.zeros((2, 2, 2), int),
              pred_occ=np.zeros((2, 2, 1), int)), 'sample tok7: pred_occ'),
        (_sample([0] * 7 + [4], [0] * 8, 'tok8'), r'tok8: gt_occ .*\[4\]'),
        (_sample([0] * 8, [0] * 7 + [255], 'tok9'), r'tok9: pred_occ'),
        (dict(sample_idx='tok10', gt_occ=np.zeros((2, 2, 2)),
              pred_occ=np.zeros((2, 2, 2), int)), 'tok10: expected integer'),
    ]
    for sample, message in bad:
        with pytest.raises(ValueError, match=message):
            metric.process({}, [sample])
    with pytest.raises(ValueError, match='tok11 has no mask_camera'):
        OccupancyMetric(convention='occ3d').process(
            {}, [_sample([17] * 8, [17] * 8, 'tok11')])
    with pytest.raises(ValueError, match='convention'):
        OccupancyMetric(convention='kitti')
    with pytest.raises(ValueError, match='voxel_size'):
        OccupancyMetric(distance_ranges=[(0, 20)])
    assert metric.results == []


def test_empty_inputs_give_nan():
    """No sample at all, or only ignored voxels: every score is NaN."""
    metrics, _ = _run(OccupancyMetric(class_names=SURROUND4), [])
    assert math.isnan(metrics['IoU']) and math.isnan(metrics['mIoU'])
    metrics, _ = _run(
        OccupancyMetric(class_names=SURROUND4),
        [_sample([255] * 8, [1] * 8)])
    assert all(math.isnan(v) for v in metrics.values())


def test_defaults_registry_and_prefix():
    """Default class lists, METRICS build, and 'occ/' prefixed keys from
    BaseMetric.evaluate (one perfect sample -> 100 %)."""
    from mmdet3d.registry import METRICS
    assert len(SURROUNDOCC_CLASSES) == 17 and SURROUNDOCC_CLASSES[0] == \
        'empty'
    assert len(OCC3D_CLASSES) == 18 and OCC3D_CLASSES[-1] == 'free'
    metric = METRICS.build(dict(type='OccupancyMetric', convention='occ3d'))
    assert isinstance(metric, OccupancyMetric) and metric.empty_index == 17
    labels = torch.arange(16).reshape(4, 4, 1)
    metric.process({}, [dict(sample_idx=0, gt_occ=labels, pred_occ=labels,
                             mask_camera=torch.ones(4, 4, 1, dtype=bool))])
    with mock.patch('projects.occ_common.evaluation.occupancy_metric.'
                    'print_log'):
        metrics = metric.evaluate(size=1)
    assert metrics['occ/mIoU'] == pytest.approx(100.0)
    assert metrics['occ/IoU'] == pytest.approx(100.0)
    assert math.isnan(metrics['occ/vegetation'])


def test_default_classes_are_the_label_formats():
    """The metric's default class lists are the loaders' (one table, in
    datasets/), with the empty class where each convention puts it:
    SurroundOcc 'empty' = 0 = OCC_FORMATS empty_label, Occ3D 'free' = 17;
    so label k means the same class in GT, loss and metric."""
    from projects.occ_common.datasets.occ_formats import OCC_FORMATS
    for convention in ('surroundocc', 'occ3d'):
        metric = OccupancyMetric(convention=convention)
        spec = OCC_FORMATS[convention]
        assert metric.class_names == spec.class_names
        assert metric.empty_index == spec.empty_label


def test_confusion_file_holds_the_dataset_matrix(tmp_path):
    """Two samples; the CSV holds their summed matrix, rows GT.

    sample 1 (as in test_surroundocc_hand_computed, voxel 5 ignored):
        (0,0) x2, (0,1), (1,1) x2, (1,2), (2,0)
    sample 2: gt 3 3 3 3 0 0 0 0, pred 3 3 2 0 0 0 0 0
        (3,3) x2, (3,2), (3,0), (0,0) x4
    sum: empty row 6 1 0 0; a 0 2 1 0; b 1 0 0 0; c 1 0 1 2
    """
    path = tmp_path / 'sub' / 'confusion.csv'
    metric = OccupancyMetric(class_names=SURROUND4, confusion_file=str(path))
    _run(metric, [
        _sample([0, 0, 1, 1, 2, 255, 0, 1], [0, 1, 1, 1, 0, 3, 0, 2]),
        _sample([3, 3, 3, 3, 0, 0, 0, 0], [3, 3, 2, 0, 0, 0, 0, 0], 's1'),
    ])
    assert path.read_text().splitlines() == [
        'gt \\ pred,empty,a,b,c', 'empty,6,1,0,0', 'a,0,2,1,0', 'b,1,0,0,0',
        'c,1,0,1,2'
    ]
    names, counts = read_confusion_csv(str(path))
    assert names == list(SURROUND4)
    assert counts.tolist() == [[6, 1, 0, 0], [0, 2, 1, 0], [1, 0, 0, 0],
                               [1, 0, 1, 2]]


def test_no_confusion_file_by_default(tmp_path, monkeypatch):
    """Without the option nothing is written (here: in the cwd)."""
    monkeypatch.chdir(tmp_path)
    _run(OccupancyMetric(class_names=SURROUND4),
         [_sample([0, 1, 1, 1, 0, 0, 0, 0], [0, 1, 0, 1, 0, 0, 0, 0])])
    assert list(tmp_path.iterdir()) == []
