"""WeightsOnlyCheckpointHook stores history buffers as data and back."""
import io

import numpy as np
import torch
from mmengine.logging.history_buffer import HistoryBuffer

from projects.occ_common.hooks import WeightsOnlyCheckpointHook


def test_round_trip_through_weights_only_torch_load():
    """Save -> weights-only load -> restore keeps the logged values.

    The buffer logs 1.0, 3.0 with counts 1, 2; mmengine's mean is
    sum(log) / sum(count) = (1 + 3) / (1 + 2) = 4 / 3 and current is 3.0.
    """
    import projects.occ_common  # noqa: F401  (allow-lists numpy types)
    buffer = HistoryBuffer([1.0, 3.0], [1, 2], max_length=10)
    checkpoint = dict(
        message_hub=dict(
            log_scalars=dict(loss=buffer), runtime_info=dict(iter=7),
            resumed_keys=dict(loss=True, iter=True)))
    hook = WeightsOnlyCheckpointHook()
    hook.before_save_checkpoint(None, checkpoint)
    stored = checkpoint['message_hub']['log_scalars']['loss']
    assert isinstance(stored, dict)

    blob = io.BytesIO()
    torch.save(checkpoint, blob)
    blob.seek(0)
    loaded = torch.load(blob, weights_only=True)
    hook.after_load_checkpoint(None, loaded)
    restored = loaded['message_hub']['log_scalars']['loss']
    assert isinstance(restored, HistoryBuffer)
    log, count = restored.data
    np.testing.assert_array_equal(log, [1.0, 3.0])
    np.testing.assert_array_equal(count, [1, 2])
    assert restored.max_length == 10
    assert restored.current() == 3.0
    assert restored.mean() == 4.0 / 3.0
    assert loaded['message_hub']['runtime_info'] == dict(iter=7)


def test_checkpoint_without_message_hub_is_left_alone():
    """A bare state-dict checkpoint passes through both hooks unchanged."""
    checkpoint = dict(state_dict=dict(w=torch.ones(2)))
    hook = WeightsOnlyCheckpointHook()
    hook.before_save_checkpoint(None, checkpoint)
    hook.after_load_checkpoint(None, checkpoint)
    assert list(checkpoint) == ['state_dict']
