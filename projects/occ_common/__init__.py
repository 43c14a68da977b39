"""Shared parts of the occupancy plugins, registered once.

Importing this package registers its datasets, transforms, models, metrics,
hooks and visualisers into the mmdet3d registries, and nothing else: the
restricted checkpoint loader (:mod:`.utils.safe_pickle`) is installed by
``WeightsOnlyCheckpointHook`` before a Runner loads anything, and by
``tools/test.py``. Configs import it with
``custom_imports = dict(imports=['projects.occ_common'])``.
"""
from . import (datasets, evaluation, hooks, models, transforms, utils,
               visualization)

__all__ = [
    'datasets', 'evaluation', 'hooks', 'models', 'transforms', 'utils',
    'visualization'
]
