"""Load every checkpoint of a run through the restricted unpickler.

:func:`~projects.occ_common.fileio.safe_pickle.install_checkpoint_loader`
makes mmengine load the checkpoints of every scheme (local, ``http(s)``,
``open-mmlab://`` ...) with the restricted loader of
:mod:`projects.occ_common.fileio.safe_pickle`, which reads Runner
checkpoints, zoo checkpoints included, and refuses anything else by name
(a TorchScript archive by what it is). Nothing is installed on import:
this hook does it in ``before_run``, which ``Runner.train`` / ``val`` /
``test`` call before they initialise weights, load or resume.

Earlier versions of this hook stored the message hub's ``HistoryBuffer``\\ s
of a checkpoint as tagged dicts (so that no ``getattr`` was pickled); the
restricted unpickler now rebuilds the buffers themselves, so new
checkpoints keep mmengine's layout, and :meth:`after_load_checkpoint`
still turns the dicts of those older checkpoints back into buffers.
"""
from typing import Dict

from mmdet3d.registry import HOOKS
from mmengine.hooks import Hook
from mmengine.logging.history_buffer import HistoryBuffer

from ...fileio.atomic_file_backend import register_atomic_backend
from ...fileio.checkpoint_schemes import install_checkpoint_loader

#: Marks a dict that stands for a ``HistoryBuffer`` in an older checkpoint.
BUFFER_TAG = '__history_buffer__'


def dict_to_buffer(state: Dict) -> HistoryBuffer:
    """Rebuild a ``HistoryBuffer`` stored as a tagged dict.

    Args:
        state (dict): ``log_history`` and ``count_history`` (arrays) and
            ``max_length`` (int), tagged with :data:`BUFFER_TAG`.

    Returns:
        HistoryBuffer: The buffer.
    """
    return HistoryBuffer(
        list(state['log_history']), list(state['count_history']),
        state['max_length'])


@HOOKS.register_module()
class WeightsOnlyCheckpointHook(Hook):
    """Install the restricted checkpoint loader before the Runner loads.

    Listed in ``custom_hooks`` of ``configs/_base_/default_runtime.py``.
    ``before_run`` also registers the ``atomic_local`` file backend, for
    configs that name it in a plain ``CheckpointHook``.
    """

    priority = 'VERY_HIGH'

    def before_run(self, runner) -> None:
        """Install the loader (once per process)."""
        install_checkpoint_loader()
        register_atomic_backend()

    def after_load_checkpoint(self, runner, checkpoint: dict) -> None:
        """Rebuild the tagged buffers of an older checkpoint."""
        hub = checkpoint.get('message_hub')
        if hub is None:
            return
        hub['log_scalars'] = {
            key: dict_to_buffer(value)
            if isinstance(value, dict) and value.get(BUFFER_TAG) else value
            for key, value in hub['log_scalars'].items()
        }
