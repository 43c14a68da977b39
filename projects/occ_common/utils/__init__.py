"""Utilities of the occupancy plugins."""
from .safe_pickle import (CHECKPOINT_GLOBALS, INFO_GLOBALS, CorruptFileError,
                          RefusedGlobalError, UnsafeCheckpointError,
                          install_checkpoint_loader, load_checkpoint_file,
                          load_info_file)
from .split_dataset import add_split_arguments, build_split_dataset
from .trained_model import build_trained_model

#: The name of :func:`load_checkpoint_file` in earlier versions.
load_weights_only = load_checkpoint_file

__all__ = [
    'CHECKPOINT_GLOBALS', 'CorruptFileError', 'INFO_GLOBALS',
    'RefusedGlobalError', 'UnsafeCheckpointError', 'add_split_arguments',
    'build_split_dataset', 'build_trained_model',
    'install_checkpoint_loader', 'load_checkpoint_file', 'load_info_file',
    'load_weights_only'
]
