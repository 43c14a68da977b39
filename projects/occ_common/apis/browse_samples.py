"""The samples the browser viewer shows: a config's test dataset, with a
model's or a ``--format-only`` folder's predictions.

Each sample runs through the config's test pipeline, so its points,
cameras and grid are in one frame (the label format's) as the model sees
them; the pipeline also reads nuScenes-lidarseg point labels where the
info file has them (``LoadLidarSegLabels(optional=True)`` is added after
the key frame's loader when the pipeline lacks it). A model's prediction
comes from its ``predict`` (what ``tools/test.py`` scores) and the
probability of the predicted class from a second, ``tensor``-mode pass
(the logits), kept only where both agree on every voxel.
"""
import copy
import warnings
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch
from mmengine.dataset import pseudo_collate

from ..evaluation.prediction_files import prediction_path, read_prediction
from ..visualization.orientation import sample_forward
from ..visualization.palette import convention_classes
from ..visualization.sample_figure import camera_images, sample_name
from ..visualization.web.scene_payload import encode_sample
from .unlabelled_pipeline import innermost_dataset

#: The pipeline step after which point labels are loaded.
KEY_FRAME_LOADER = 'LoadOccPointsFromFile'


def label_settings(cfg) -> Tuple[str, Tuple[str, ...], int]:
    """Convention, class names and empty label of a config's test metric.

    Args:
        cfg (Config): The config.

    Returns:
        tuple: ``(convention, class_names, empty_label)``; the metric's
        ``convention`` (else the test dataset's ``occ_format``, else
        SurroundOcc's) and its ``class_names`` if it names them.
    """
    evaluator = cfg.get('test_evaluator', {})
    metrics = evaluator if isinstance(evaluator, list) else [evaluator]
    metric = next((m for m in metrics if 'convention' in m), {})
    dataset = innermost_dataset(cfg.test_dataloader.dataset)
    convention = metric.get('convention',
                            dataset.get('occ_format', 'surroundocc'))
    names, empty = convention_classes(convention)
    if metric.get('class_names'):
        names = tuple(metric['class_names'])
    return convention, tuple(names), empty


def with_point_labels(dataset_cfg: Dict) -> Dict:
    """``dataset_cfg`` whose pipeline also loads lidarseg labels.

    Args:
        dataset_cfg (dict): The test dataset's config (any wrapper).

    Returns:
        dict: A copy; ``LoadLidarSegLabels(optional=True)`` follows the
        first ``LoadOccPointsFromFile`` unless the pipeline loads labels
        already or has no such loader.
    """
    dataset_cfg = copy.deepcopy(dataset_cfg)
    inner = innermost_dataset(dataset_cfg)
    steps = list(inner['pipeline'])
    types = [step.get('type') for step in steps]
    if 'LoadLidarSegLabels' not in types and KEY_FRAME_LOADER in types:
        at = types.index(KEY_FRAME_LOADER) + 1
        steps.insert(at, dict(type='LoadLidarSegLabels', optional=True))
        inner['pipeline'] = steps
    return dataset_cfg


def _numpy(value) -> Optional[np.ndarray]:
    if value is None:
        return None
    if torch.is_tensor(value):
        return value.detach().cpu().numpy()
    return np.asarray(value)


class BrowseSamples:
    """Sample ``index`` of a dataset as the viewer's message.

    Args:
        dataset (BaseDataset): Yields packed samples (``inputs``,
            ``data_samples``) through the test pipeline.
        convention (str): ``'surroundocc'`` or ``'occ3d'``.
        class_names (Sequence[str]): Names in label order.
        empty_label (int): Label of empty space.
        model (nn.Module, optional): From
            :func:`~projects.occ_common.apis.init_model`; predicts each
            sample. Defaults to None.
        pred_dir (str, optional): A ``tools/test.py --format-only`` folder
            to read predictions from instead. Defaults to None.
        with_prob (bool): Show the model's probability of its class.
            Defaults to True.
        all_sweeps (bool): Draw the merged sweeps' points too, not only the
            key frame's. Defaults to False.
        max_points (int, optional): Draw at most this many points (a seeded
            random choice). Defaults to None (all).
    """

    def __init__(self, dataset, convention: str, class_names: Sequence[str],
                 empty_label: int, model=None, pred_dir: Optional[str] = None,
                 with_prob: bool = True, all_sweeps: bool = False,
                 max_points: Optional[int] = None) -> None:
        if model is not None and pred_dir is not None:
            raise ValueError('give a model or a prediction folder, not both')
        self.dataset = dataset
        self.convention = convention
        self.class_names = tuple(class_names)
        self.empty_label = empty_label
        self.model = model
        self.pred_dir = pred_dir
        self.with_prob = with_prob
        self.all_sweeps = all_sweeps
        self.max_points = max_points

    def __len__(self) -> int:
        return len(self.dataset)

    def encode(self, index: int) -> Tuple[bytes, List[bytes]]:
        """The message and camera JPEGs of sample ``index``."""
        return encode_sample(self.scene(index), len(self.class_names),
                             self.empty_label)

    def scene(self, index: int) -> Dict:
        """What the viewer draws of sample ``index`` (the ``scene`` of
        :func:`~projects.occ_common.visualization.web.encode_sample`).

        Raises:
            ValueError: A prediction file is missing or malformed (naming
                it), or the model's output does not fit the grid.
        """
        packed = self.dataset[index]
        sample = packed['data_samples']
        meta = sample.metainfo
        scene = dict(
            name=sample_name(sample, str(index)),
            token=meta.get('token'),
            scene_name=meta.get('scene_name'),
            sample_idx=meta.get('sample_idx', index),
            is_rainy=bool(meta.get('is_rainy', False)),
            is_night=bool(meta.get('is_night', False)),
            forward=sample_forward(meta.get('lidar2ego'),
                                   meta.get('occ_format', self.convention)),
            pc_range=meta['occ_pc_range'],
            voxel_size=meta['occ_voxel_size'])
        for key in ('gt_occ', 'mask_camera', 'mask_lidar'):
            scene[key] = _numpy(getattr(sample, key, None))
        if self.model is not None:
            scene.update(self._predict(packed))
        elif self.pred_dir is not None:
            shape = self._grid_shape(scene)
            scene['pred_occ'] = read_prediction(
                prediction_path(self.pred_dir, self.convention, meta),
                shape, self.empty_label)
        scene.update(self._points(packed['inputs'], sample))
        scene.update(self._cameras(packed['inputs'], meta))
        return scene

    def _grid_shape(self, scene: Dict) -> Tuple[int, ...]:
        if scene.get('gt_occ') is not None:
            return scene['gt_occ'].shape
        extent = np.asarray(scene['pc_range'][3:]) - np.asarray(
            scene['pc_range'][:3])
        return tuple(np.rint(extent / np.asarray(
            scene['voxel_size'])).astype(int).tolist())

    def _predict(self, packed: Dict) -> Dict:
        """``pred_occ`` (and ``pred_prob``) of the model."""
        model = self.model
        with torch.no_grad():
            data = model.data_preprocessor(pseudo_collate([packed]), False)
            output = model(**data, mode='predict')[0]
            pred = _numpy(output.pred_occ)
            result = dict(pred_occ=pred)
            if not self.with_prob:
                return result
            logits = model(**data, mode='tensor')
        if isinstance(logits, (list, tuple)):
            logits = logits[0]  # finest scale first
        if not torch.is_tensor(logits) or logits.dim() != 5 or \
                tuple(logits.shape[2:]) != pred.shape:
            warnings.warn('browse_occ: the model\'s tensor output is not '
                          '(B, C, X, Y, Z) logits of the grid: no '
                          'probabilities shown.')
            self.with_prob = False
            return result
        prob, label = logits.float().softmax(1)[0].max(0)
        if not np.array_equal(label.cpu().numpy(), pred):
            warnings.warn('browse_occ: the argmax of the model\'s logits '
                          'differs from its prediction (another branch '
                          'predicts): no probabilities shown.')
            self.with_prob = False
            return result
        result['pred_prob'] = prob.cpu().numpy()
        return result

    def _points(self, inputs: Dict, sample) -> Dict:
        points = _numpy(inputs.get('points'))
        if points is None:
            return {}
        labels = None
        if 'gt_pts_seg' in sample and \
                'pts_semantic_mask' in sample.gt_pts_seg:
            labels = _numpy(sample.gt_pts_seg.pts_semantic_mask)
        keep = np.ones(len(points), dtype=bool)
        time_dim = sample.metainfo.get('points_time_dim')
        if not self.all_sweeps and time_dim is not None and \
                points.shape[1] > time_dim:
            # The key frame's points have a time lag of 0.
            keep &= np.abs(points[:, time_dim]) < 1e-6
        if self.max_points is not None and keep.sum() > self.max_points:
            chosen = np.random.default_rng(0).choice(
                np.flatnonzero(keep), self.max_points, replace=False)
            keep = np.zeros_like(keep)
            keep[chosen] = True
        return dict(points=points[keep],
                    point_labels=None if labels is None else labels[keep])

    def _cameras(self, inputs: Dict, meta: Dict) -> Dict:
        img = inputs.get('img')
        lidar2img = meta.get('lidar2img')
        if img is None or lidar2img is None:
            return {}
        lidar2img = np.asarray(lidar2img, dtype=np.float64)
        # A temporal config packs the previous key frames' views after the
        # current ones, which lidar2img describes.
        images = camera_images(img)[:len(lidar2img)]
        names = list(meta.get('cam_names') or [])[:len(images)]
        return dict(images=images, lidar2img=lidar2img, cam_names=names)
