"""Hooks of the occupancy plugins.

Importing this package also registers the ``atomic_local`` file backend
(:mod:`.atomic_file_backend`) with mmengine.
"""
from .atomic_file_backend import AtomicLocalBackend, atomic_write
from .checkpoint_recovery_hook import CheckpointRecoveryHook
from .non_finite_loss_hook import NonFiniteLossError, NonFiniteLossHook
from .occ_visualization_hook import OccVisualizationHook
from .weights_only_checkpoint_hook import WeightsOnlyCheckpointHook

__all__ = [
    'AtomicLocalBackend', 'CheckpointRecoveryHook', 'NonFiniteLossError',
    'NonFiniteLossHook', 'OccVisualizationHook', 'WeightsOnlyCheckpointHook',
    'atomic_write'
]
