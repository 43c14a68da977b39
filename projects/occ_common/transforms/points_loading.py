"""LiDAR key-frame and multi-sweep loading with checked files.

Subclasses of mmdet3d's loaders that keep their keys and options and add
what they lack: a missing or truncated ``.bin`` raises an error naming the
file (mmdet3d's give a bare reshape error), as does a file of another
dtype or point width (read as float32 x 5 it would give garbage points);
points with NaN / inf values are dropped with one warning per file, giving
their count; and sweeps are moved into the key frame with the exact
inverse of ``lidar2sensor``. mmdet3d 1.4's
``LoadPointsFromMultiSweeps`` computes ``p @ R - t`` from
``lidar2sensor = [R | t]``, i.e. ``R^T p - t`` instead of
``R^T (p - t)`` (open-mmlab/mmdetection3d#3054): the sweep is shifted by
``(R^T - I) t``, which grows with the ego's turn rate and speed (about
0.5 m for a 10 m/s car turning at 0.1 rad/s, 0.5 s back).
"""
import warnings
from typing import Optional, Sequence

import numpy as np
from mmdet3d.datasets.transforms import (LoadPointsFromFile,
                                         LoadPointsFromMultiSweeps)
from mmdet3d.registry import TRANSFORMS

from ..datasets.info_format import NUM_POINT_FEATS
from ..fileio.input_files import MAX_INPUT_BYTES, read_input_bytes
from .ego_points import check_ego_box, remove_ego_from_sweep

#: Files already warned about (one warning per file and process).
_WARNED = set()

#: Column of the ring (beam) index in nuScenes' x, y, z, intensity, ring.
RING_COLUMN = 4


def _check_ring_column(points: np.ndarray, path: str, what: str) -> None:
    """Refuse a nuScenes-layout file whose ring column is not beam indices.

    A float64 file, or one of 4 values a point, read as 5 float32 values
    has the right size more often than not; its fifth column is then
    fractions or garbage instead of the integers 0..255 of a beam index.
    """
    ring = points[:, RING_COLUMN]
    ring = ring[np.isfinite(ring)]
    bad = (ring != np.round(ring)) | (ring < 0) | (ring > 255)
    if bad.any():
        raise ValueError(
            f'{what} file {path}: the fifth value of {int(bad.sum())} of its '
            f'{len(points)} points (e.g. {ring[bad][0]!r}) is no ring '
            'index (an integer 0..255, as in nuScenes files of x, y, z, '
            'intensity, ring as float32): the file holds another dtype '
            '(float64?) or another number of values per point. Convert it '
            'to 5 float32 values a point, or pass check_ring=False if its '
            'fifth value is something else.')


def with_time_lag(points: np.ndarray, lag: float) -> np.ndarray:
    """Points with the time lag as column 4: written over a fifth value
    (nuScenes' ring index), appended to x, y, z, intensity.

    Args:
        points (np.ndarray): Shape (P, C), C >= 4; changed in place when
            C >= 5.
        lag (float): Seconds before the key frame.

    Returns:
        np.ndarray: Shape (P, max(C, 5)), float32.
    """
    if points.shape[1] == 4:
        return np.concatenate(
            [points, np.full((len(points), 1), lag, points.dtype)], axis=1)
    points[:, 4] = lag
    return points


def _seconds(value, where: str) -> float:
    """A timestamp in seconds, refusing strings and other non-numbers."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(
            value, (int, float, np.integer, np.floating)):
        raise ValueError(f'{where} must be a number of seconds, got '
                         f'{type(value).__name__} {value!r:.40}')
    return float(value)


def finite_rows(points: np.ndarray, path: str, what: str) -> np.ndarray:
    """Which points have only finite values; warn once per file if not all.

    Args:
        points (np.ndarray): Shape (P, C).
        path (str): The file, for the warning.
        what (str): What it is, for the warning.

    Returns:
        np.ndarray: Shape (P,), bool.
    """
    kept = np.isfinite(points).all(axis=1)
    dropped = int(len(kept) - kept.sum())
    if dropped and path not in _WARNED:
        _WARNED.add(path)
        share = 'all' if dropped == len(kept) else f'{dropped} of'
        warnings.warn(
            f'{what} file {path}: {share} {len(kept)} points have NaN / inf '
            'values and are dropped.')
    return kept


def read_points_file(path: str,
                     load_dim: int,
                     what: str = 'LiDAR points',
                     backend_args: Optional[dict] = None,
                     drop_nonfinite: bool = True,
                     check_ring: bool = True) -> np.ndarray:
    """Read a float32 point file (``.bin``) and check its size and layout.

    Args:
        path (str): File to read.
        load_dim (int): Values per point.
        what (str): What the file is, for error messages.
            Defaults to 'LiDAR points'.
        backend_args (dict, optional): mmengine file backend arguments.
        drop_nonfinite (bool): Drop the points with NaN / inf values (one
            warning per file, see :func:`finite_rows`). Defaults to True.
        check_ring (bool): With ``load_dim`` 5 (nuScenes' x, y, z,
            intensity, ring), refuse a file whose fifth values are not
            ring indices. Defaults to True.

    Returns:
        np.ndarray: Shape (P, load_dim), float32, writable. P may be 0.

    Raises:
        FileNotFoundError: The file does not exist.
        ValueError: It is no regular file or larger than
            ``MAX_INPUT_BYTES['points']``, its size is not a whole number
            of points, or its ring column holds no ring indices (another
            dtype or point width).
    """
    # A regular file within the size limit: a device or FIFO would never
    # end or block.
    raw = read_input_bytes(path, f'{what} file', MAX_INPUT_BYTES['points'],
                           backend_args)
    point_bytes = 4 * load_dim
    if len(raw) % point_bytes:
        raise ValueError(
            f'{what} file {path} has {len(raw)} bytes, not a multiple of '
            f'{point_bytes} ({load_dim} float32 values per point): the file '
            'is truncated or has another layout')
    points = np.frombuffer(raw, dtype=np.float32).reshape(-1, load_dim)
    if check_ring and load_dim == NUM_POINT_FEATS:
        _check_ring_column(points, path, what)
    if drop_nonfinite:
        kept = finite_rows(points, path, what)
        if not kept.all():
            return points[kept]
    return points.copy()


@TRANSFORMS.register_module()
class LoadOccPointsFromFile(LoadPointsFromFile):
    """mmdet3d's ``LoadPointsFromFile`` with a checked file read.

    Same arguments, keys and behaviour as the parent (``coord_type``,
    ``load_dim``, ``use_dim``, ...); a missing file or one whose size is
    not a multiple of ``load_dim`` float32 values raises an error naming
    the file. nuScenes files hold x, y, z, intensity, ring (``load_dim=5``):
    a file whose ring column is not beam indices (another dtype or point
    width) is refused, as is a ``load_dim`` other than the sample's
    ``num_pts_feats``. ``load_dim=None`` takes each sample's
    ``num_pts_feats`` instead, so that one pipeline reads nuScenes' files
    and those of a LiDAR without ring index (x, y, z, intensity). Points
    with NaN / inf values are dropped (one warning per file), and
    ``points_kept_rows`` tells ``LoadLidarSegLabels`` which rows of the
    file are left. An empty file is a valid sample with zero points.

    Args:
        load_dim (int, optional): Values per point in the files; None for
            the sample's ``num_pts_feats``. Defaults to 6 (the parent's).
        use_dim (int | list[int]): Columns kept (an int ``n``: the first
            ``n``). Defaults to [0, 1, 2] (the parent's).
        check_ring (bool): Refuse a 5-value file whose fifth values are not
            ring indices. Defaults to True.
        **kwargs: The other arguments of ``LoadPointsFromFile``.

    Required Keys:

    - lidar_points (dict): ``lidar_path``.
    - num_pts_feats (int, optional): Values per point the info records.

    Added Keys:

    - points (BasePoints): Shape (P, len(use_dim)).
    - points_kept_rows (np.ndarray, optional): Shape (P_file,), bool;
      only if points were dropped.
    """

    def __init__(self,
                 load_dim: Optional[int] = 6,
                 use_dim=(0, 1, 2),
                 check_ring: bool = True,
                 **kwargs) -> None:
        use_dim = list(range(use_dim)) if isinstance(use_dim, int) \
            else list(use_dim)
        # The parent checks use_dim against load_dim; with load_dim None
        # that check runs per sample (transform).
        super().__init__(
            load_dim=max(use_dim) + 1 if load_dim is None else load_dim,
            use_dim=use_dim, **kwargs)
        self.load_dim = load_dim
        self.check_ring = check_ring
        self._kept_rows = None

    def _load_points(self, pts_filename: str) -> np.ndarray:
        """Read the key frame as a flat float32 array of finite points."""
        points = read_points_file(pts_filename, self.load_dim,
                                  'LiDAR key frame', self.backend_args,
                                  drop_nonfinite=False,
                                  check_ring=self.check_ring)
        kept = finite_rows(points, pts_filename, 'LiDAR key frame')
        # Handed to transform() right after this call returns.
        self._kept_rows = None if kept.all() else kept
        return (points if kept.all() else points[kept]).reshape(-1)

    def transform(self, results: dict) -> dict:
        """Load the key frame (see the class doc).

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The state with ``points``.

        Raises:
            ValueError: If the info's ``num_pts_feats`` is not
                ``load_dim``, or the file is refused.
        """
        recorded = results.get('num_pts_feats')
        where = (f'{results.get("ann_file", "the info file")}: sample '
                 f'{results.get("token", "?")}')
        if self.load_dim is None:
            if recorded is None:
                raise ValueError(
                    f'{where} records no num_pts_feats; give '
                    'LoadOccPointsFromFile the values per point (load_dim)')
            return self._transform_as(int(recorded), results, where)
        if recorded is not None and int(recorded) != self.load_dim:
            raise ValueError(
                f'{where} records {recorded} values per '
                f'LiDAR point (num_pts_feats), but load_dim is '
                f'{self.load_dim}: {results["lidar_points"]["lidar_path"]} '
                'would be read as garbage points.')
        results = super().transform(results)
        if self._kept_rows is not None:
            results['points_kept_rows'] = self._kept_rows
            self._kept_rows = None
        return results

    def _transform_as(self, load_dim: int, results: dict,
                      where: str) -> dict:
        """:meth:`transform` with the sample's ``load_dim`` (the parent
        reads ``self.load_dim``)."""
        if max(self.use_dim) >= load_dim:
            raise ValueError(
                f'{where} has {load_dim} values per LiDAR point '
                f'(num_pts_feats), fewer than use_dim {self.use_dim} needs')
        try:
            self.load_dim = load_dim
            return self.transform(results)
        finally:
            self.load_dim = None

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (super().__repr__()[:-1] +
                f', check_ring={self.check_ring})')


@TRANSFORMS.register_module()
class LoadOccPointsFromMultiSweeps(LoadPointsFromMultiSweeps):
    """Merge earlier LiDAR sweeps into the key frame, exactly.

    Same arguments, sweep choice (all if there are at most ``sweeps_num``,
    else a random subset in training, the newest in ``test_mode``) and
    output layout as mmdet3d's ``LoadPointsFromMultiSweeps``: column 4 of
    the merged points is the time lag in seconds (0 for the key frame),
    then ``use_dim`` is applied. Differences:

    * sweep points go to the key frame with ``sensor2lidar`` (or the exact
      inverse of ``lidar2sensor``), see the module docstring;
    * missing / truncated sweep files, and files of another dtype or point
      width, raise an error naming the file; points with NaN / inf values
      are dropped with one warning per file;
    * ``ego_box`` removes the ego vehicle's returns from every sweep in its
      own sensor frame (see :mod:`.ego_points`), a box round the car where
      ``remove_close`` is a 1 m sphere round the sensor;
    * a key-frame ``pts_semantic_mask`` is padded with ``ignore_index``
      for the sweep points, so that it stays aligned with ``points``;
    * points of four values (x, y, z, intensity: a key frame loaded with
      ``use_dim=4``, or the files of a LiDAR without ring index) get the
      time lag appended as their column 4 instead of written over it.

    Args:
        sweeps_num (int): Sweeps to merge. Defaults to 10.
        load_dim (int, optional): Values per point in the files; None for
            the key frame's ``num_pts_feats`` (one sensor, one layout).
            Defaults to 5.
        use_dim (list[int]): Columns kept. Defaults to [0, 1, 2, 3, 4]
            (x, y, z, intensity, time lag).
        ignore_index (int): Label of sweep points in
            ``pts_semantic_mask``. Defaults to 255.
        ego_box (Sequence[float], optional): ``(x0, y0, z0, x1, y1, z1)``
            in the ego frame: sweep points inside are dropped. A sweep's
            ``lidar_points.lidar2ego`` places it (the key frame's
            ``lidar2ego`` when the sweep has none: one sensor, one mount).
            Defaults to None (kept).
        check_ring (bool): Refuse a ``load_dim=5`` sweep whose fifth
            values are not ring indices (another dtype or point width).
            Defaults to True.
        record_ring (bool): Keep every merged point's ring (beam) index,
            which the time lag replaces in ``points``, as
            ``points_ring``, for a transform right after this one that
            needs it (``OccCorruption``'s beam reduction, which removes
            it again: later filters would not keep it aligned). Defaults
            to False.
        **kwargs: ``backend_args``, ``pad_empty_sweeps``, ``remove_close``,
            ``test_mode`` of the parent.

    Required Keys:

    - points (BasePoints): Key frame, at least 4 columns.
    - timestamp (float): Key-frame time in seconds.
    - num_pts_feats (int, optional): Values per point of the files, for
      ``load_dim=None``.
    - lidar_sweeps (list[dict], optional): ``lidar_points.lidar_path``,
      ``lidar_points.lidar2sensor`` (or ``sensor2lidar``), ``timestamp``
      (and ``lidar_points.lidar2ego`` for ``ego_box``).
    - lidar2ego (np.ndarray, optional): Shape (4, 4), for ``ego_box``.
    - pts_semantic_mask (np.ndarray, optional): Shape (P_key,).

    Modified Keys:

    - points: Shape (P_key + P_sweeps, len(use_dim)).
    - pts_semantic_mask: Shape (P_key + P_sweeps,).

    Added Keys:

    - points_time_dim (int | None): Column of the time lag in ``points``
      (None if ``use_dim`` drops it).
    - points_ring (np.ndarray): Shape (P_key + P_sweeps,), int16, the ring
      index of every point; only with ``record_ring``.
    """

    def __init__(self,
                 sweeps_num: int = 10,
                 load_dim: Optional[int] = 5,
                 use_dim=(0, 1, 2, 3, 4),
                 ignore_index: int = 255,
                 ego_box: Optional[Sequence[float]] = None,
                 check_ring: bool = True,
                 record_ring: bool = False,
                 **kwargs) -> None:
        use_dim = list(range(use_dim)) if isinstance(use_dim, int) \
            else list(use_dim)
        if load_dim is not None and load_dim < 4:
            raise ValueError('LoadOccPointsFromMultiSweeps needs files of at '
                             'least x, y, z, intensity (load_dim >= 4), got '
                             f'load_dim={load_dim}')
        # Column 4 (the time lag) exists whatever the files hold: the
        # parent's check of use_dim against load_dim does not apply.
        super().__init__(
            sweeps_num=sweeps_num,
            load_dim=max(use_dim + [4]) + 1,
            use_dim=use_dim,
            **kwargs)
        self.load_dim = load_dim
        self.ignore_index = ignore_index
        self.ego_box = None if ego_box is None else check_ego_box(ego_box)
        self.check_ring = check_ring
        self.record_ring = record_ring

    def _ring(self, points: np.ndarray, path) -> Optional[np.ndarray]:
        """A copy of the ring column of ``points`` with ``record_ring``
        (None without), refusing files that have none."""
        if not self.record_ring:
            return None
        if points.shape[1] <= RING_COLUMN:
            raise ValueError(
                f'{self.__class__.__name__}(record_ring=True) needs the ring '
                f'index (the fifth value of a point), but {path} holds '
                f'{points.shape[1]} values a point (a LiDAR without ring '
                'index): a transform that drops beams cannot run on it')
        return points[:, RING_COLUMN].copy()

    @staticmethod
    def sweep_to_key(sweep: dict) -> np.ndarray:
        """The 4x4 sweep-LiDAR -> key-frame-LiDAR transform of a sweep."""
        pts = sweep['lidar_points']
        if 'sensor2lidar' in pts:
            return np.asarray(pts['sensor2lidar'], dtype=np.float64)
        return np.linalg.inv(np.asarray(pts['lidar2sensor'], np.float64))

    def _choose(self, num_sweeps: int) -> np.ndarray:
        if num_sweeps <= self.sweeps_num:
            return np.arange(num_sweeps)
        if self.test_mode:
            return np.arange(self.sweeps_num)
        return np.random.choice(num_sweeps, self.sweeps_num, replace=False)

    def _merge(self, points, parts: list):
        """One points object of the ``use_dim`` columns of all parts."""
        if points.attribute_dims is not None:
            merged = points.new_point(np.concatenate(parts))
            return merged[:, self.use_dim]
        # Fast path: one copy into the output instead of mmdet3d's
        # new_point / cat / getitem copies (~3x less time on 10 sweeps).
        out = np.empty((sum(len(p) for p in parts), len(self.use_dim)),
                       dtype=np.float32)
        start = 0
        for part in parts:
            out[start:start + len(part)] = part[:, self.use_dim]
            start += len(part)
        return type(points)(out, points_dim=out.shape[1])

    def transform(self, results: dict) -> dict:
        """Merge the sweeps of one sample.

        Args:
            results (dict): Pipeline state (see Required Keys).

        Returns:
            dict: The state with merged ``points``.
        """
        points = results['points']
        if points.tensor.shape[1] < 4:
            raise ValueError(
                f'{self.__class__.__name__} needs key-frame points with at '
                f'least 4 columns (x, y, z, intensity; column 4 becomes the '
                f'time lag), got {points.tensor.shape[1]} for '
                f'{results.get("lidar_path")}')
        key_ring = self._ring(points.tensor.numpy(),
                              results.get('lidar_path'))
        key = with_time_lag(points.tensor.numpy(), 0.0)
        load_dim = self.load_dim or int(results.get(
            'num_pts_feats', NUM_POINT_FEATS))
        parts, rings = [key], [key_ring]
        sweeps = results.get('lidar_sweeps')
        if sweeps is None:
            if self.pad_empty_sweeps:
                # The ring rides along as a last column through the filter.
                pad = key if key_ring is None else np.column_stack(
                    [key, key_ring])
                if self.remove_close:
                    pad = self._remove_close(pad)
                if key_ring is not None:
                    rings += [pad[:, -1]] * self.sweeps_num
                    pad = pad[:, :-1]
                parts += [pad] * self.sweeps_num
        else:
            token = results.get('token', '?')
            key_time = _seconds(results['timestamp'],
                                f'sample {token}: timestamp')
            for idx in self._choose(len(sweeps)):
                sweep = sweeps[idx]
                path = sweep['lidar_points']['lidar_path']
                sweep_time = _seconds(
                    sweep['timestamp'],
                    f'sample {token}: timestamp of sweep {path}')
                arr = read_points_file(
                    path, load_dim,
                    f'LiDAR sweep of sample {results.get("token", "?")}',
                    self.backend_args, check_ring=self.check_ring)
                if self.remove_close:
                    # In the sweep's own frame, where "close" means the car.
                    arr = self._remove_close(arr)
                if self.ego_box is not None:
                    arr = remove_ego_from_sweep(
                        arr,
                        sweep['lidar_points'].get('lidar2ego',
                                                  results.get('lidar2ego')),
                        self.ego_box)
                mat = self.sweep_to_key(sweep).astype(np.float32)
                arr[:, :3] = arr[:, :3] @ mat[:3, :3].T + mat[:3, 3]
                rings.append(self._ring(arr, path))
                parts.append(with_time_lag(arr, key_time - sweep_time))
        num_key = len(points)
        if key.shape[1] != points.tensor.shape[1]:  # time lag appended
            points = type(points)(key, points_dim=key.shape[1])
        results['points'] = self._merge(points, parts)
        # Tells later transforms which column separates key frame / sweeps.
        results['points_time_dim'] = self.use_dim.index(4) \
            if 4 in self.use_dim else None
        if self.record_ring:
            results['points_ring'] = np.concatenate(rings).astype(np.int16)
        if 'pts_semantic_mask' in results:
            key_mask = np.asarray(results['pts_semantic_mask'])
            pad = np.full(len(results['points']) - num_key, self.ignore_index,
                          key_mask.dtype)
            results['pts_semantic_mask'] = np.concatenate([key_mask, pad])
        return results

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}(sweeps_num={self.sweeps_num}, '
                f'load_dim={self.load_dim}, use_dim={self.use_dim}, '
                f'remove_close={self.remove_close}, '
                f'ego_box={self.ego_box}, test_mode={self.test_mode}, '
                f'record_ring={self.record_ring})')
