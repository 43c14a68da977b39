"""OccCorruption: one seeded sensor corruption, applied on the fly."""
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS

from .conditions import CONDITIONS, MAX_SEVERITY
from .seeding import corruption_rng


@TRANSFORMS.register_module()
class OccCorruption(BaseTransform):
    """Corrupt a loaded sample's cameras, LiDAR or their alignment.

    One of :attr:`CONDITIONS` (see :mod:`.conditions` and
    docs/robustness.md for what each does at each severity) is applied to
    the sample as it is loaded, so no corrupted copy of the dataset is
    written. Place it right after the loading transforms (points, sweeps,
    images) and before the image augmentation, where the views are still
    the camera's uint8 pixels and the points still in the sensor's frame;
    ``tools/analysis_tools/robustness.py`` inserts it there.

    Every random draw comes from a generator seeded by (sample token,
    condition, ``seed``): the same input always comes out the same, in any
    worker and order. The severities of a condition share the draws, so a
    higher one corrupts each sample more, never differently (see
    :mod:`.seeding`).

    Two conditions need more than the loaded sample: ``beam_reduction``
    needs each point's ring index
    (``LoadOccPointsFromMultiSweeps(record_ring=True)``), ``frame_lost``
    the previous key frame (``NuScenesOccDataset(num_frames=2)``).

    Args:
        condition (str): One of :attr:`CONDITIONS`.
        severity (int): 1 (mild) .. :attr:`MAX_SEVERITY`.
        seed (int): Seed of the run. Defaults to 0.

    Required Keys:

    - token (str) or sample_idx (int): names the sample's draws.
    - img (list[np.ndarray]): uint8 views, Shape (H, W, 3); per-view
      ``cam2img``, ``lidar2cam``, ``lidar2img``, ... (N, 4, 4).
    - points (BasePoints): Shape (P, C).
    - points_ring, prev_frames, lidar_sweeps, timestamp: as the condition
      needs them.

    Modified Keys:

    - img, points, pts_semantic_mask, and for the view and calibration
      conditions the per-view keys (``missing_views`` drops views).

    Added Keys:

    - corruption (dict): ``condition``, ``severity``, ``seed``.
    - corruption_delay_s (float): ``temporal_misalignment`` only.
    """

    #: Names of the conditions, camera first, then LiDAR, then both.
    CONDITIONS = tuple(CONDITIONS)
    #: The highest severity; every condition has levels 1..MAX_SEVERITY.
    MAX_SEVERITY = MAX_SEVERITY

    def __init__(self, condition: str, severity: int, seed: int = 0) -> None:
        if condition not in CONDITIONS:
            raise ValueError(f'OccCorruption: unknown condition '
                             f'{condition!r}; known: {self.CONDITIONS}')
        if isinstance(severity, bool) or not isinstance(severity, int) or \
                not 1 <= severity <= MAX_SEVERITY:
            raise ValueError(f'OccCorruption: severity must be an integer '
                             f'1..{MAX_SEVERITY}, got {severity!r}')
        self.condition = condition
        self.severity = severity
        self.seed = int(seed)
        self._spec = CONDITIONS[condition]

    @property
    def level(self):
        """The condition's parameter at this severity (see
        :mod:`.conditions`)."""
        return self._spec.levels[self.severity - 1]

    def transform(self, results: dict) -> dict:
        """Corrupt one sample.

        Args:
            results (dict): Pipeline state after the loading transforms.

        Returns:
            dict: The corrupted state.
        """
        sample = results.get('token', results.get('sample_idx'))
        if sample is None:
            raise ValueError(
                'OccCorruption needs the sample\'s token (or sample_idx) to '
                f'seed its draws; the pipeline state has {sorted(results)}')
        rng = corruption_rng(str(sample), self.condition, self.seed)
        self._spec.apply(results, self.level, rng)
        # The ring indices served this transform; later filters would not
        # keep them aligned with the points.
        results.pop('points_ring', None)
        results['corruption'] = dict(
            condition=self.condition, severity=self.severity, seed=self.seed)
        return results

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}(condition={self.condition!r}, '
                f'severity={self.severity}, seed={self.seed})')
