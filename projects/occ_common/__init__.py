"""Shared parts of the occupancy plugins, registered once.

Importing this package registers its datasets, transforms, models, metrics,
hooks and visualisers into the mmdet3d registries, and installs the
weights-only checkpoint loader (:mod:`.utils.safe_checkpoint`). Configs do
that with ``custom_imports = dict(imports=['projects.occ_common'])``.
"""
from . import (datasets, evaluation, hooks, models, transforms, utils,
               visualization)
from .utils.safe_checkpoint import install as _install_safe_checkpoint

_install_safe_checkpoint()

__all__ = [
    'datasets', 'evaluation', 'hooks', 'models', 'transforms', 'utils',
    'visualization'
]
