"""The viewer's samples on the tiny world: labels, predictions, points and
cameras as the test pipeline gives them."""
import numpy as np
import pytest
import torch
from mmengine.config import Config
from mmengine.registry import DATASETS, MODELS, init_default_scope

from projects.occ_common.apis import init_model
from projects.occ_common.apis.browse_samples import (BrowseSamples,
                                                     label_settings,
                                                     with_point_labels)
from projects.occ_common.evaluation.occupancy_export import \
    write_occ3d_prediction
from projects.occ_common.visualization.palette import convention_classes
from projects.occ_common.visualization.web import encode_sample, unpack_message

CONFIG = 'configs/sdg_occ/sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py'
FREE, CAR = 17, 4
#: Occ3D's class names and empty label (free).
OCC3D = convention_classes('occ3d')


@pytest.fixture(scope='module')
def cfg(converted_tiny_world):
    cfg = Config.fromfile(CONFIG)
    cfg.test_dataloader.dataset.data_root = converted_tiny_world
    init_default_scope('mmdet3d')
    return cfg


@pytest.fixture(scope='module')
def dataset(cfg):
    return DATASETS.build(with_point_labels(cfg.test_dataloader.dataset))


def _labels(dataset, index):
    with np.load(dataset.get_data_info(index)['occ_path']) as data:
        return data['semantics'], data['mask_camera'], data['mask_lidar']


def test_label_settings_and_point_labels_step(cfg):
    """The Occ3D config's metric: 18 classes, free (17) empty. The step
    that loads lidarseg labels is added right after the key frame's loader
    of a pipeline without it, and never twice."""
    convention, names, empty = label_settings(cfg)
    assert (convention, len(names), empty) == ('occ3d', 18, FREE)
    plain = dict(type='X', pipeline=[dict(type='LoadOccPointsFromFile'),
                                     dict(type='PackOccInputs')])
    added = with_point_labels(plain)['pipeline']
    assert [s['type'] for s in added] == [
        'LoadOccPointsFromFile', 'LoadLidarSegLabels', 'PackOccInputs']
    assert added[1]['optional'] and len(plain['pipeline']) == 2
    assert with_point_labels(dict(type='X', pipeline=added))[
        'pipeline'] == added


def test_scene_from_a_format_only_folder(dataset, tmp_path):
    """Sample 0 with a prediction file that is the GT with its first 5
    car voxels made free: the message's GT and masks are the label file's,
    the prediction the file's, and the errors count exactly those 5 misses
    (no false positive, no wrong class). The points are the key frame's
    (time lag 0), each with a lidarseg class (1..16) or 255; six cameras
    each have a frustum and a JPEG."""
    gt, mask_camera, mask_lidar = _labels(dataset, 0)
    pred = gt.copy()
    cars = np.argwhere(gt == CAR)[:5]
    pred[tuple(cars.T)] = FREE
    token = dataset.get_data_info(0)['token']
    write_occ3d_prediction(str(tmp_path), token, pred)
    samples = BrowseSamples(dataset, 'occ3d', *OCC3D,
                            pred_dir=str(tmp_path))
    scene = samples.scene(0)
    np.testing.assert_array_equal(scene['gt_occ'], gt)
    np.testing.assert_array_equal(scene['pred_occ'], pred)
    np.testing.assert_array_equal(scene['mask_camera'], mask_camera)
    assert scene['token'] == token and scene['forward'] == '+x'
    message, jpegs = samples.encode(0)
    header, arrays = unpack_message(message)
    assert header['counts']['errors'][1:] == [0, 5, 0]
    assert header['counts']['gt'] == int((gt != FREE).sum())
    np.testing.assert_array_equal(
        arrays['visibility'].reshape(gt.shape),
        mask_camera.astype(np.uint8) | mask_lidar.astype(np.uint8) << 1)
    labels = arrays['points_label']
    assert len(labels) == header['counts']['points'] > 100
    assert set(np.unique(labels)) <= set(range(1, 17)) | {255}
    assert (labels != 255).mean() > 0.5
    assert len(jpegs) == len(header['cameras']) == 6
    assert all(j[:2] == b'\xff\xd8' for j in jpegs)  # JPEG files


def test_missing_prediction_file_is_named(dataset, tmp_path):
    samples = BrowseSamples(dataset, 'occ3d', *OCC3D,
                            pred_dir=str(tmp_path))
    token = dataset.get_data_info(1)['token']
    with pytest.raises(FileNotFoundError, match=f'{token}.npz'):
        samples.scene(1)


@pytest.mark.slow
def test_model_prediction_and_probability(cfg, dataset, tmp_path):
    """A checkpoint of the tiny SDG-Fusion (seeded, untrained), loaded by
    init_model: the message's prediction is the model's ``predict``
    output, and every predicted voxel's probability is the softmax
    maximum, at least 1 / 18 (stored as uint8: >= round(255 / 18) =
    14)."""
    torch.manual_seed(0)
    path = str(tmp_path / 'model.pth')
    torch.save({'meta': {}, 'state_dict': MODELS.build(cfg.model)
                .state_dict()}, path)
    model = init_model(cfg, path)
    samples = BrowseSamples(dataset, 'occ3d', *OCC3D,
                            model=model)
    scene = samples.scene(0)
    prob, pred = scene['pred_prob'], scene['pred_occ']
    assert pred.shape == prob.shape == (200, 200, 16)
    assert prob.min() >= 1 / 18 - 1e-6 and prob.max() <= 1
    header, arrays = unpack_message(encode_sample(scene, 18, FREE)[0])
    np.testing.assert_array_equal(arrays['pred'].reshape(pred.shape), pred)
    assert len(arrays['prob']) == int((pred != FREE).sum())
    assert arrays['prob'].min() >= 14
