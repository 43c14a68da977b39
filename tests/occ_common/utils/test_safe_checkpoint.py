"""Weights-only checkpoint loading: exact allow-list, malicious refusal."""
import os
import os.path as osp
import subprocess
import sys

import pytest
import torch

import projects.occ_common  # noqa: F401  (installs the loader)
from projects.occ_common.utils import (CHECKPOINT_SAFE_GLOBALS,
                                       UnsafeCheckpointError,
                                       load_weights_only)

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.dirname(
    osp.abspath(__file__)))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


class _Evil:
    """Pickles as a call to ``os.system`` that would create ``marker``."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f'touch {self.marker}', ))


def _qualname(obj):
    return f'{obj.__module__}.{obj.__qualname__}'


@pytest.fixture(scope='module')
def runner_checkpoint(tmp_path_factory):
    """A real Runner checkpoint of the toy config (1 epoch)."""
    work_dir = str(tmp_path_factory.mktemp('ckpt'))
    proc = subprocess.run([
        sys.executable,
        osp.join(ROOT, 'tools', 'train.py'), CONFIG, '--work-dir', work_dir,
        '--cfg-options', 'train_cfg.max_epochs=1'
    ],
                          cwd=ROOT,
                          capture_output=True,
                          text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return osp.join(work_dir, 'epoch_1.pth')


def test_allow_list_covers_exactly_what_runner_checkpoints_pickle(
        runner_checkpoint):
    """The allow-list is exactly the non-default globals of a checkpoint.

    ``get_unsafe_globals_in_checkpoint`` lists the globals outside torch's
    default allow-list and the user-added one; with ours cleared for the
    call it must give exactly ours but the dtype classes, which are not
    globals of the pickle but types rebuilt by BUILD: numpy's ndarray, dtype
    and the array and scalar reconstructors. The checkpoint then loads, so
    the dtype classes listed suffice.
    """
    user_globals = torch.serialization.get_safe_globals()
    torch.serialization.clear_safe_globals()
    try:
        unsafe = set(
            torch.serialization.get_unsafe_globals_in_checkpoint(
                runner_checkpoint))
    finally:
        torch.serialization.add_safe_globals(user_globals)
    allowed = {_qualname(obj) for obj in CHECKPOINT_SAFE_GLOBALS}
    dtype_classes = {'numpy.dtypes.Float64DType', 'numpy.dtypes.Int64DType'}
    assert unsafe == allowed - dtype_classes
    # WeightsOnlyCheckpointHook stored the buffers as data, not objects.
    assert 'builtins.getattr' not in unsafe
    assert not any('HistoryBuffer' in name for name in unsafe)
    ckpt = load_weights_only(runner_checkpoint)
    assert set(ckpt) >= {'meta', 'state_dict', 'message_hub', 'optimizer'}


def test_malicious_checkpoint_is_refused_and_not_executed(tmp_path):
    """A pickled ``os.system`` call is refused by name; nothing runs."""
    marker = tmp_path / 'pwned'
    path = str(tmp_path / 'evil.pth')
    torch.save({'state_dict': {}, 'meta': _Evil(marker)}, path)
    with pytest.raises(UnsafeCheckpointError) as err:
        load_weights_only(path)
    message = str(err.value)
    assert path in message
    assert 'system' in message
    assert not marker.exists()


def test_tools_test_refuses_malicious_checkpoint(tmp_path):
    """tools/test.py exits non-zero naming the file; nothing is executed."""
    marker = tmp_path / 'pwned'
    path = str(tmp_path / 'evil.pth')
    torch.save({'state_dict': {}, 'meta': _Evil(marker)}, path)
    proc = subprocess.run([
        sys.executable,
        osp.join(ROOT, 'tools', 'test.py'), CONFIG, path, '--work-dir',
        str(tmp_path / 'work')
    ],
                          cwd=ROOT,
                          capture_output=True,
                          text=True,
                          timeout=300)
    assert proc.returncode != 0
    assert f'Refusing to load checkpoint {path}' in proc.stderr
    assert not marker.exists()


def test_missing_checkpoint_names_the_file(tmp_path):
    """A path that is not a file raises FileNotFoundError naming it."""
    path = str(tmp_path / 'nope.pth')
    with pytest.raises(FileNotFoundError, match='nope.pth'):
        load_weights_only(path)
