"""Where OccCorruption goes in a config's pipeline."""
import copy
from typing import List, Sequence

from .conditions import CONDITIONS

#: Transforms that load a sample's inputs (this library's and mmdet3d's):
#: OccCorruption goes right after the last of them.
INPUT_LOADERS = ('LoadOccPointsFromFile', 'RemoveEgoPoints',
                 'LoadLidarSegLabels', 'LoadOccPointsFromMultiSweeps',
                 'LoadMultiViewImagesOcc', 'LoadPointsFromFile',
                 'LoadPointsFromMultiSweeps', 'LoadMultiViewImageFromFiles')
#: The sweeps loader that can keep the ring indices (``record_ring``).
SWEEPS_LOADER = 'LoadOccPointsFromMultiSweeps'
#: The key-frame loader: its points carry the ring to the sweeps loader.
KEY_FRAME_LOADER = 'LoadOccPointsFromFile'


def _type(transform: dict) -> str:
    """A transform config's registered name without its scope."""
    return str(transform.get('type', '')).split('.')[-1]


def keep_rings(pipeline: List[dict]) -> None:
    """Make a pipeline keep the ring (beam) index of every point.

    The dataset configs load x, y, z, intensity of the key frame (the
    files' point layout comes from the info file, and a LiDAR without ring
    index has no fifth value); here the key-frame loader keeps the files'
    fifth value too, the ring, as column 4 (which the sweeps loader
    records, then overwrites with the time lag), and the sweeps loader
    records every merged point's ring (``record_ring=True``). On files of
    four values a point the key-frame loader then fails, naming the sample.

    Args:
        pipeline (list[dict]): Transform configs, changed in place.
    """
    for transform in pipeline:
        if _type(transform) == KEY_FRAME_LOADER:
            use_dim = transform.get('use_dim', 5)
            if isinstance(use_dim, int):
                transform['use_dim'] = max(use_dim, 5)
            elif 4 not in use_dim:
                transform['use_dim'] = sorted(list(use_dim) + [4])
        elif _type(transform) == SWEEPS_LOADER:
            transform['record_ring'] = True


def with_corruption(pipeline: Sequence[dict], condition: str,
                    severity: int, seed: int = 0) -> List[dict]:
    """A copy of ``pipeline`` that corrupts its samples.

    ``OccCorruption(condition, severity, seed)`` goes right after the last
    of the :data:`INPUT_LOADERS`; for a condition that needs the ring
    indices, the loaders keep them (:func:`keep_rings`).

    Args:
        pipeline (Sequence[dict]): Transform configs, e.g. a config's
            ``test_dataloader.dataset.pipeline``.
        condition (str): One of ``OccCorruption.CONDITIONS``.
        severity (int): 1..``OccCorruption.MAX_SEVERITY``.
        seed (int): Seed of the run. Defaults to 0.

    Returns:
        list[dict]: The new pipeline (the given one is not changed).

    Raises:
        ValueError: For an unknown condition, or a pipeline without any of
            the input loaders.
    """
    if condition not in CONDITIONS:
        raise ValueError(f'unknown corruption {condition!r}; known: '
                         f'{tuple(CONDITIONS)}')
    pipeline = [copy.deepcopy(dict(t)) for t in pipeline]
    loaders = [i for i, t in enumerate(pipeline)
               if _type(t) in INPUT_LOADERS]
    if not loaders:
        raise ValueError(
            'the pipeline loads no inputs with any of '
            f'{INPUT_LOADERS}; it has {[_type(t) for t in pipeline]}')
    if CONDITIONS[condition].needs == 'ring':
        keep_rings(pipeline)
    corruption = dict(type='OccCorruption', condition=condition,
                      severity=int(severity), seed=int(seed))
    return (pipeline[:loaders[-1] + 1] + [corruption] +
            pipeline[loaders[-1] + 1:])
