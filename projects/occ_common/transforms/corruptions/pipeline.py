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


def _type(transform: dict) -> str:
    """A transform config's registered name without its scope."""
    return str(transform.get('type', '')).split('.')[-1]


def with_corruption(pipeline: Sequence[dict], condition: str,
                    severity: int, seed: int = 0) -> List[dict]:
    """A copy of ``pipeline`` that corrupts its samples.

    ``OccCorruption(condition, severity, seed)`` goes right after the last
    of the :data:`INPUT_LOADERS`; for a condition that needs the ring
    indices, the sweeps loader keeps them (``record_ring=True``).

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
        for transform in pipeline:
            if _type(transform) == SWEEPS_LOADER:
                transform['record_ring'] = True
    corruption = dict(type='OccCorruption', condition=condition,
                      severity=int(severity), seed=int(seed))
    return (pipeline[:loaders[-1] + 1] + [corruption] +
            pipeline[loaders[-1] + 1:])
