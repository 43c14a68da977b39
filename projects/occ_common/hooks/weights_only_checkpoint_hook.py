"""Keep Runner checkpoints loadable with ``torch.load(weights_only=True)``.

mmengine's ``HistoryBuffer.__getstate__`` adds its statistics functions
(``HistoryBuffer.min`` ...) to the pickled state; pickle protocol 2 (torch's
default) writes them as ``getattr(HistoryBuffer, 'min')``. Allowing
``builtins.getattr`` in the weights-only unpickler would let a checkpoint
reach any attribute of any allowed object, so instead this hook stores each
buffer of the message hub as a plain dict when a checkpoint is saved and
rebuilds the buffers when one is loaded, before the Runner restores its
message hub. A checkpoint then holds only tensors, containers, primitives
and numpy arrays / scalars (see :mod:`projects.occ_common.utils.
safe_checkpoint`).
"""
from typing import Dict

import numpy as np
from mmdet3d.registry import HOOKS
from mmengine.hooks import Hook
from mmengine.logging.history_buffer import HistoryBuffer

#: Marks a dict that stands for a ``HistoryBuffer`` in a checkpoint.
BUFFER_TAG = '__history_buffer__'


def buffer_to_dict(buffer: HistoryBuffer) -> Dict:
    """The data of a ``HistoryBuffer`` as a dict of arrays and an int."""
    log_history, count_history = buffer.data
    return {
        BUFFER_TAG: True,
        'log_history': np.asarray(log_history),
        'count_history': np.asarray(count_history),
        'max_length': int(buffer.max_length),
    }


def dict_to_buffer(state: Dict) -> HistoryBuffer:
    """Rebuild the ``HistoryBuffer`` stored by :func:`buffer_to_dict`."""
    return HistoryBuffer(
        list(state['log_history']), list(state['count_history']),
        state['max_length'])


@HOOKS.register_module()
class WeightsOnlyCheckpointHook(Hook):
    """Store the message hub's history buffers as plain data.

    Listed in ``custom_hooks`` of ``configs/_base_/default_runtime.py`` so
    that every config of this library writes checkpoints that load with
    ``weights_only=True``.
    """

    priority = 'VERY_LOW'

    def before_save_checkpoint(self, runner, checkpoint: dict) -> None:
        """Replace each ``HistoryBuffer`` by :func:`buffer_to_dict`."""
        hub = checkpoint.get('message_hub')
        if hub is None:
            return
        hub['log_scalars'] = {
            key: buffer_to_dict(value)
            if isinstance(value, HistoryBuffer) else value
            for key, value in hub['log_scalars'].items()
        }

    def after_load_checkpoint(self, runner, checkpoint: dict) -> None:
        """Rebuild the buffers before the Runner restores its message hub."""
        hub = checkpoint.get('message_hub')
        if hub is None:
            return
        hub['log_scalars'] = {
            key: dict_to_buffer(value)
            if isinstance(value, dict) and value.get(BUFFER_TAG) else value
            for key, value in hub['log_scalars'].items()
        }
