"""RayIoU (SparseOcc's ray-based metric) as an mmengine metric."""
import hashlib
import logging
import math
import os
import os.path as osp
import tempfile
from typing import Dict, Optional, Sequence

import numpy as np
from mmdet3d.registry import METRICS
from mmengine.evaluator import BaseMetric
from mmengine.logging import print_log

from ..datasets.nuscenes_classes import OCC3D_CLASS_NAMES
from ..fileio.input_files import MAX_INPUT_BYTES, check_input_file
from .ray_casting import RAY_PC_RANGE, RAY_VOXEL_SIZE, RayHits, cast_rays
from .ray_iou import (RAY_IOU_THRESHOLDS, count_ray_hits, ray_iou_from_counts,
                      to_numpy)
from .ray_origins import info_path, load_origin_frames


def _hits_digest(hits: RayHits) -> str:
    """SHA-1 of the cached arrays (dtypes, shapes and bytes)."""
    digest = hashlib.sha1()
    for array in hits:
        array = np.ascontiguousarray(array)
        digest.update(repr((array.dtype.str, array.shape)).encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


@METRICS.register_module(name='OccRayIoUMetric')
class RayIoUMetric(BaseMetric):
    """RayIoU of Occ3D-nuScenes predictions (SparseOcc, Liu et al., ECCV
    2024), exact to SparseOcc's evaluation code (:mod:`.ray_iou`).

    Registered as ``'OccRayIoUMetric'``. Every sample's rays are cast
    through its prediction and ground truth on the CPU (numpy; ranks of a
    distributed test work in parallel) and reduced to ray counts per class
    (a few hundred integers), which are gathered and pooled over the whole
    set in :meth:`compute_metrics`. It runs alone or beside
    :class:`.OccupancyMetric`, e.g.::

        val_evaluator = [
            dict(type='OccupancyMetric', convention='occ3d'),
            dict(type='OccRayIoUMetric', data_root=data_root,
                 ann_file='nuscenes_occ_infos_val.pkl'),
        ]

    Each data sample given to :meth:`process` is a dict with ``pred_occ``
    and ``gt_occ`` (integer labels, Shape (200, 200, 16), Occ3D's ego
    frame, without the camera mask: a masked label such as 255 is refused)
    and its ray origins: ``ray_origins`` (Shape (T, 3), metres, ego frame)
    when the pipeline packs them, else looked up by the sample's ``token``
    in the origins of ``ann_file`` (:func:`.load_ray_origins`, read once).

    With ``cache_gt_rays`` what the ground truth's rays hit is kept per
    sample (about 0.56 MB each, 3.4 GB for the 6,019 val samples, split
    over the ranks), so that later evaluations (every validation of a
    training run) cast the prediction alone; with ``gt_cache_dir`` it is
    kept on disk instead, across runs. Entries are keyed by a hash of the
    GT grid, the origins and the protocol, so a changed label is never
    served stale; a file holds its key and a digest of its hits, so one
    replaced or damaged on disk is cast again (with a warning naming it).

    Origins read from ``ann_file`` belong to the sample of the same token
    there: a sample whose packed ``timestamp`` or ``ego2global`` differs
    (the dataloader's roots overridden, the metric's not) is refused.

    Args:
        ann_file (str, optional): Info file of the evaluated split, for
            the origins. Defaults to None (samples carry ``ray_origins``).
        data_root (str, optional): Folder ``ann_file`` is relative to.
            Defaults to None.
        class_names (Sequence[str], optional): Label names. Defaults to
            Occ3D's 18 (17 = ``free``).
        free_index (int, optional): Free label, left out of the means.
            Defaults to the last.
        thresholds (Sequence[float]): Depth tolerances, metres.
            Defaults to (1, 2, 4).
        pc_range (Sequence[float]): Grid extent, ego frame. Defaults to
            Occ3D's ``(-40, -40, -1, 40, 40, 5.4)``.
        voxel_size (float): Voxel edge, metres. Defaults to 0.4.
        cache_gt_rays (bool): Keep the GT's ray hits in memory.
            Defaults to False.
        gt_cache_dir (str, optional): Keep them as ``.npz`` files in this
            folder instead (created if needed). Defaults to None.
        collect_device (str): Device to gather results on. Defaults to
            'cpu'.
        prefix (str, optional): Key prefix. Defaults to ``'occ'``.
        collect_dir (str, optional): Directory for CPU gathering.
            Defaults to None.
    """

    default_prefix = 'occ'

    def __init__(self,
                 ann_file: Optional[str] = None,
                 data_root: Optional[str] = None,
                 class_names: Optional[Sequence[str]] = None,
                 free_index: Optional[int] = None,
                 thresholds: Sequence[float] = RAY_IOU_THRESHOLDS,
                 pc_range: Sequence[float] = RAY_PC_RANGE,
                 voxel_size: float = RAY_VOXEL_SIZE,
                 cache_gt_rays: bool = False,
                 gt_cache_dir: Optional[str] = None,
                 collect_device: str = 'cpu',
                 prefix: Optional[str] = None,
                 collect_dir: Optional[str] = None) -> None:
        super().__init__(
            collect_device=collect_device,
            prefix=prefix,
            collect_dir=collect_dir)
        self.ann_file = ann_file
        self.data_root = data_root
        self.class_names = tuple(class_names or OCC3D_CLASS_NAMES)
        self.num_classes = len(self.class_names)
        if free_index is None:
            free_index = self.num_classes - 1
        self.free_index = int(free_index)
        if not 0 <= self.free_index < self.num_classes:
            raise ValueError(f'RayIoUMetric: free_index {free_index} is not '
                             f'a label of {self.class_names}.')
        self.thresholds = tuple(float(t) for t in thresholds)
        self.pc_range = tuple(float(v) for v in pc_range)
        self.voxel_size = float(voxel_size)
        self.grid_shape = tuple(
            int(round((self.pc_range[i + 3] - self.pc_range[i]) /
                      self.voxel_size)) for i in range(3))
        self.gt_cache_dir = gt_cache_dir
        self.cache_gt_rays = bool(cache_gt_rays) or gt_cache_dir is not None
        self._gt_cache: Dict[str, RayHits] = {}
        self._origins_by_token: Optional[Dict[str, np.ndarray]] = None
        self._frames_by_token: Dict[str, tuple] = {}

    def process(self, data_batch, data_samples: Sequence[dict]) -> None:
        """Cast the rays of a batch and store their counts.

        Args:
            data_batch: Unused; the predictions carry everything.
            data_samples (Sequence[dict]): See the class docstring.
        """
        for sample in data_samples:
            name = sample.get('token', sample.get('sample_idx',
                                                  f'#{len(self.results)}'))
            pred = self._labels(sample, 'pred_occ', name)
            gt = self._labels(sample, 'gt_occ', name)
            origins = self._origins(sample, name)
            key = self._cache_key(gt, origins) if self.cache_gt_rays else None
            gt_hits = self._cached(key)
            if gt_hits is None:
                pred_hits, gt_hits = self._cast([pred, gt], origins)
                self._store(key, gt_hits)
            else:
                # Rays whose GT hits nothing are dropped: skip them.
                pred_hits, = self._cast([pred], origins,
                                        gt_hits.label != self.free_index)
            self.results.append(
                count_ray_hits(pred_hits, gt_hits, self.num_classes,
                               self.free_index, self.thresholds))

    def _cast(self, grids, origins, only=None):
        """:func:`.cast_rays` with the metric's grid and free label."""
        return cast_rays(grids, origins, free_index=self.free_index,
                         pc_range=self.pc_range, voxel_size=self.voxel_size,
                         only=only)

    def _labels(self, sample: dict, key: str, name) -> np.ndarray:
        """An integer label grid of the sample, checked."""
        if sample.get(key) is None:
            raise ValueError(f'RayIoUMetric: sample {name} has no {key}.')
        value = to_numpy(sample[key])
        if not np.issubdtype(value.dtype, np.integer):
            raise ValueError(f'RayIoUMetric: sample {name}: expected integer '
                             f'{key}, got {value.dtype}.')
        if value.shape != self.grid_shape:
            raise ValueError(
                f'RayIoUMetric: sample {name}: expected {key} of shape '
                f'{self.grid_shape} (pc_range / voxel_size), got '
                f'{value.shape}.')
        if value.size and (value.min() < 0
                           or value.max() >= self.num_classes):
            raise ValueError(
                f'RayIoUMetric: sample {name}: {key} has labels outside '
                f'[0, {self.num_classes}) (found {value.min()}..'
                f'{value.max()}); RayIoU needs whole grids, without an '
                'ignore label (load the GT without mask_with).')
        return value

    def _origins(self, sample: dict, name) -> np.ndarray:
        """The sample's ray origins: packed, or from ``ann_file``."""
        if sample.get('ray_origins') is not None:
            origins = to_numpy(sample['ray_origins']).astype(np.float64)
            return origins.reshape(-1, 3)
        if self.ann_file is None:
            raise ValueError(
                f'RayIoUMetric: sample {name} has no ray_origins; give the '
                'metric the ann_file (and data_root) of the split.')
        if self._origins_by_token is None:
            self._origins_by_token, self._frames_by_token = \
                load_origin_frames(self.ann_file, self.data_root)
        token = sample.get('token')
        if token not in self._origins_by_token:
            raise ValueError(
                f'RayIoUMetric: sample {name} (token {token!r}) is not in '
                f'{self.ann_file}; give the info file of the evaluated '
                'split.')
        self._check_same_frame(sample, name, token)
        return self._origins_by_token[token]

    def _check_same_frame(self, sample: dict, name, token: str) -> None:
        """Refuse origins of another dataset's sample of the same token.

        The metric reads the origins from its own ``data_root`` /
        ``ann_file``, which a config states once; a run whose dataloader
        roots are overridden (``--cfg-options``) evaluated another dataset
        with these origins. The sample's packed ``timestamp`` and
        ``ego2global`` must be those of the info file's entry (samples
        without them cannot be checked).

        Raises:
            ValueError: Naming the sample, the info file and what differs.
        """
        timestamp, ego2global = self._frames_by_token[token]
        theirs = sample.get('ego2global')
        differs = []
        if sample.get('timestamp') is not None and not math.isclose(
                float(sample['timestamp']), timestamp, abs_tol=1e-6):
            differs.append(f'timestamp {sample["timestamp"]} vs {timestamp}')
        if theirs is not None and not np.allclose(
                to_numpy(theirs).astype(np.float64).reshape(4, 4),
                ego2global, atol=1e-4):
            differs.append('ego2global')
        if differs:
            raise ValueError(
                f'RayIoUMetric: sample {name} is not the sample of token '
                f'{token} in {info_path(self.ann_file, self.data_root)} '
                f'({", ".join(differs)} differ): the metric would cast '
                "rays from another dataset's origins. Set the metric's "
                "data_root and ann_file to the evaluated dataset's (an "
                'override of the dataloader roots does not change them).')

    def _cache_key(self, gt: np.ndarray, origins: np.ndarray) -> str:
        """Hash of everything the GT's ray hits depend on."""
        digest = hashlib.sha1()
        digest.update(repr((gt.shape, gt.dtype.str, self.free_index,
                            self.pc_range, self.voxel_size)).encode())
        digest.update(np.ascontiguousarray(gt).tobytes())
        digest.update(np.ascontiguousarray(origins, np.float64).tobytes())
        return digest.hexdigest()

    def _cached(self, key: Optional[str]) -> Optional[RayHits]:
        """The cached GT hits under ``key``, if any."""
        if key is None:
            return None
        if self.gt_cache_dir is None:
            return self._gt_cache.get(key)
        path = osp.join(self.gt_cache_dir, f'{key}.npz')
        if not osp.isfile(path):
            return None
        problem = None
        try:
            check_input_file(path, 'RayIoU GT cache file',
                             MAX_INPUT_BYTES['label'])
            with np.load(path, allow_pickle=False) as data:
                hits = RayHits(data['label'], data['depth'])
                stored = (str(data['key']), str(data['digest']))
        except (OSError, ValueError, KeyError) as err:
            problem = f'{type(err).__name__}: {err}'
        else:
            if stored != (key, _hits_digest(hits)):
                problem = ('its content is not the GT rays of this sample '
                           '(replaced or damaged)')
        if problem is not None:
            print_log(f'RayIoUMetric: ignoring the cache file {path} '
                      f'({problem}); the GT rays are cast again.',
                      logger='current', level=logging.WARNING)
            return None
        return hits

    def _store(self, key: Optional[str], hits: RayHits) -> None:
        """Cache the GT hits under ``key`` (memory, or an atomic file)."""
        if key is None:
            return
        if self.num_classes <= 256:
            hits = RayHits(hits.label.astype(np.uint8), hits.depth)
        if self.gt_cache_dir is None:
            self._gt_cache[key] = hits
            return
        os.makedirs(self.gt_cache_dir, exist_ok=True)
        # Written aside and renamed: ranks never read a half-written file.
        fd, tmp = tempfile.mkstemp(suffix='.npz', dir=self.gt_cache_dir)
        with os.fdopen(fd, 'wb') as f:
            # The key and a digest of the hits: a file replaced or damaged
            # later is recognised and cast again (_cached).
            np.savez(f, label=hits.label, depth=hits.depth,
                     key=np.array(key), digest=np.array(_hits_digest(hits)))
        os.replace(tmp, osp.join(self.gt_cache_dir, f'{key}.npz'))

    def compute_metrics(self, results: list) -> Dict[str, float]:
        """Pool the ray counts of all samples and compute RayIoU.

        Args:
            results (list[dict]): :meth:`process` outputs of all ranks.

        Returns:
            dict[str, float]: See :func:`.ray_iou_from_counts`, in percent.
        """
        total = dict(
            gt=np.zeros(self.num_classes, np.int64),
            pred=np.zeros(self.num_classes, np.int64),
            tp=np.zeros((len(self.thresholds), self.num_classes), np.int64))
        for counts in results:
            for key in total:
                total[key] += counts[key]
        metrics = ray_iou_from_counts(total, self.class_names,
                                      self.free_index, self.thresholds)
        print_log(self._table(metrics, len(results)), logger='current')
        return metrics

    def _table(self, metrics: Dict[str, float], num_samples: int) -> str:
        """Per-class RayIoU at every threshold, and the means."""
        columns = [f'RayIoU@{t:g}' for t in self.thresholds] + ['RayIoU']
        width = max(len(n) for n in self.class_names) + 2
        lines = [
            f'RayIoU (%) of {num_samples} samples:',
            'class'.ljust(width) + ''.join(c.rjust(12) for c in columns)
        ]
        for c, name in enumerate(self.class_names):
            if c != self.free_index:
                lines.append(name.ljust(width) + ''.join(
                    f'{metrics[f"{col}/{name}"]:12.2f}' for col in columns))
        lines.append('mean'.ljust(width) +
                     ''.join(f'{metrics[col]:12.2f}' for col in columns))
        return '\n'.join(lines)
