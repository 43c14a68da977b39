"""Hooks of the occupancy plugins.

Importing this package registers the hooks and nothing else; the
``atomic_local`` file backend
(:mod:`projects.occ_common.fileio.atomic_file_backend`) is registered by
the hooks that use it when they are built or run.
"""
from .augmentation_seed_hook import AugmentationSeedHook
from .checkpoint_match_hook import CheckpointMatchHook
from .checkpoint_recovery_hook import CheckpointRecoveryHook
from .cpu_malloc_tuning_hook import CPUMallocTuningHook
from .main_process_logger_hook import MainProcessLoggerHook
from .non_finite_loss_hook import NonFiniteLossError, NonFiniteLossHook
from .occ_visualization_hook import OccVisualizationHook
from .random_state_hook import RandomStateHook
from .safe_checkpoint_hook import SafeCheckpointHook
from .weights_only_checkpoint_hook import WeightsOnlyCheckpointHook
from .work_dir_lock_hook import WorkDirLockHook

__all__ = [
    'AugmentationSeedHook', 'CheckpointMatchHook',
    'CheckpointRecoveryHook', 'CPUMallocTuningHook', 'MainProcessLoggerHook',
    'NonFiniteLossError', 'NonFiniteLossHook', 'OccVisualizationHook',
    'RandomStateHook', 'SafeCheckpointHook', 'WeightsOnlyCheckpointHook',
    'WorkDirLockHook'
]
