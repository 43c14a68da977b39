"""Weights-only loading of mmengine Runner checkpoints under torch >= 2.6.

torch 2.6 made ``torch.load(weights_only=True)`` the default. mmengine
0.10.7 calls ``torch.load`` without the argument, so every Runner checkpoint
(which pickles numpy arrays, and the message hub's ``HistoryBuffer`` with
its statistics functions through ``builtins.getattr``) fails to load.
Turning weights-only loading off would execute arbitrary pickled code from a
downloaded checkpoint, so instead:

- :class:`~projects.occ_common.hooks.WeightsOnlyCheckpointHook` (in every
  config through ``configs/_base_/default_runtime.py``) stores the history
  buffers as plain dicts, so no function is pickled;
- we allow-list exactly the remaining globals of such a checkpoint, the
  numpy array and scalar reconstructors and dtypes
  (``tests/occ_common/utils/test_safe_checkpoint.py`` checks the list
  against a real checkpoint);
- mmengine's local-file loader is replaced with one that always passes
  ``weights_only=True`` and names the file and the refused globals when a
  checkpoint holds anything else.
"""
import importlib
import os.path as osp
import pickle
from typing import Callable, List, Optional, Union

import numpy as np
import torch
from mmengine.runner.checkpoint import CheckpointLoader


def _numpy_reconstruct() -> List[Callable]:
    """numpy's array and scalar reconstructors (numpy 1.x or 2.x)."""
    if np.lib.NumpyVersion(np.__version__) >= '2.0.0':
        multiarray = importlib.import_module('numpy._core.multiarray')
    else:
        multiarray = importlib.import_module('numpy.core.multiarray')
    return [multiarray._reconstruct, multiarray.scalar]


#: Every global a Runner checkpoint of this project pickles besides what
#: torch allows by default (tensors, containers, primitives): the numpy
#: arrays and scalars of the message hub's logs, with the dtype classes they
#: are rebuilt through (float64 log values, int64 counts).
CHECKPOINT_SAFE_GLOBALS: List[Union[type, Callable]] = [
    np.ndarray,
    np.dtype,
    *_numpy_reconstruct(),
    type(np.dtype(np.float64)),
    type(np.dtype(np.int64)),
]


class UnsafeCheckpointError(pickle.UnpicklingError):
    """Raised when a checkpoint pickles an object outside the allow-list."""


def register_safe_globals() -> None:
    """Add :data:`CHECKPOINT_SAFE_GLOBALS` to torch's weights-only list."""
    torch.serialization.add_safe_globals(CHECKPOINT_SAFE_GLOBALS)


def load_weights_only(filename: str,
                      map_location: Optional[Union[str, Callable]] = None):
    """Load a local checkpoint with ``weights_only=True``.

    Args:
        filename (str): Path of the checkpoint file.
        map_location (str | callable, optional): As for :func:`torch.load`.
            Defaults to None.

    Returns:
        dict: The checkpoint.

    Raises:
        FileNotFoundError: If ``filename`` is not a file.
        UnsafeCheckpointError: If the checkpoint pickles a global that is
            not allow-listed; nothing from it is executed.
    """
    filename = osp.expanduser(filename)
    if not osp.isfile(filename):
        raise FileNotFoundError(f'checkpoint {filename} can not be found.')
    try:
        return torch.load(
            filename, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as err:
        try:
            unsafe = torch.serialization.get_unsafe_globals_in_checkpoint(
                filename)
        except Exception:  # noqa: BLE001 - the listing is best effort
            unsafe = []
        if not unsafe:
            # Not a refused global but a refused type to rebuild: torch's
            # message names it.
            unsafe = [
                line.strip() for line in str(err).splitlines()
                if 'allowlisted' in line or 'Unsupported' in line
            ] or ['see the error above']
        hint = ''
        if 'builtins.getattr' in unsafe:
            hint = (' A Runner checkpoint written without '
                    'WeightsOnlyCheckpointHook pickles the statistics '
                    'functions of its HistoryBuffers through getattr; if you '
                    'trust the file, re-save it without its message_hub.')
        raise UnsafeCheckpointError(
            f'Refusing to load checkpoint {filename}: it pickles objects '
            f'outside the weights-only allow-list ({", ".join(unsafe)}). '
            'Nothing from it was executed. If you trust this file and know '
            'what these objects are, add them with '
            f'torch.serialization.add_safe_globals before loading.{hint}'
        ) from err


def _load_from_local(filename: str, map_location=None):
    """mmengine ``CheckpointLoader`` scheme for local paths."""
    return load_weights_only(filename, map_location)


def install() -> None:
    """Register the allow-list and the weights-only local loader.

    Called when :mod:`projects.occ_common` is imported (configs do that
    through ``custom_imports``), before any checkpoint is loaded. The local
    scheme ``''`` is re-registered with ``force=True`` because mmengine
    offers no other hook to pass ``weights_only`` explicitly.
    """
    register_safe_globals()
    CheckpointLoader.register_scheme(
        prefixes='', loader=_load_from_local, force=True)
