"""Restricted unpickling: zoo checkpoints and info files load, code never
runs.

The zoo-style checkpoint is written by a plain mmengine Runner (mmengine's
own ``CheckpointHook``, none of this library's hooks), as every OpenMMLab
model-zoo checkpoint is: its message hub pickles ``HistoryBuffer``\\ s and
their statistics methods as ``getattr(HistoryBuffer, 'min')``.
"""
import collections
import os
import os.path as osp
import pickle
import pickletools
import subprocess
import sys
import uuid

import mmengine
import numpy as np
import pytest
import torch
from mmengine.logging.history_buffer import HistoryBuffer
from mmengine.runner import Runner

import projects.occ_common.testing.toy_model  # noqa: F401  (registers)
from projects.occ_common.engine.hooks import WeightsOnlyCheckpointHook
from projects.occ_common.fileio import (CorruptFileError, RefusedGlobalError,
                                        UnsafeCheckpointError,
                                        load_checkpoint_file, load_info_file)
from projects.occ_common.fileio.safe_pickle import (CHECKPOINT_GLOBALS,
                                                    INFO_GLOBALS,
                                                    statistic_names)

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.dirname(
    osp.abspath(__file__)))))
REAL_INFO = osp.join(ROOT, '..', 'shared', 'data', 'nuscenes_real_sample',
                     'n015-2018-07-24-11-22-45+0800.pkl')


def _runner(work_dir, max_epochs, **kwargs):
    """A plain mmengine Runner training the toy model on 4 samples."""
    return Runner(
        model=dict(type='ToyOccupancyModel'),
        work_dir=work_dir,
        experiment_name=f'zoo_{uuid.uuid4().hex}',
        train_dataloader=dict(
            dataset=dict(type='ToyOccupancyDataset', num_samples=4),
            sampler=dict(type='DefaultSampler', shuffle=True),
            batch_size=2,
            num_workers=0),
        train_cfg=dict(by_epoch=True, max_epochs=max_epochs),
        optim_wrapper=dict(optimizer=dict(type='SGD', lr=0.1, momentum=0.9)),
        param_scheduler=dict(type='MultiStepLR', milestones=[1]),
        default_hooks=dict(
            checkpoint=dict(type='CheckpointHook', interval=1),
            logger=dict(type='LoggerHook', interval=1)),
        default_scope='mmdet3d',
        randomness=dict(seed=0),
        **kwargs)


@pytest.fixture(scope='module')
def zoo_checkpoint(tmp_path_factory):
    """epoch_1.pth of a plain mmengine Runner (no hook of this library)."""
    work_dir = str(tmp_path_factory.mktemp('zoo'))
    _runner(work_dir, 1).train()
    return osp.join(work_dir, 'epoch_1.pth')


def _globals(path):
    """``module.name`` of every global the checkpoint's pickle names."""
    import zipfile
    with zipfile.ZipFile(path) as archive:
        name = next(n for n in archive.namelist() if n.endswith('data.pkl'))
        data = archive.read(name)
    return {
        arg.replace(' ', '.').replace('__builtin__', 'builtins')
        for op, arg, _ in pickletools.genops(data) if op.name == 'GLOBAL'
    }


def test_zoo_checkpoint_pickles_exactly_these_globals(zoo_checkpoint):
    """What mmengine 0.10.7 / torch 2.13 write, each on the allow-list
    (torch 2.11 with numpy 2.5 the same, under numpy's new module name).

    Storage types (``torch.FloatStorage``) are mapped by torch.load itself
    and never reach the allow-list.
    """
    found = _globals(zoo_checkpoint)
    # numpy 2 pickles its arrays as numpy._core..., numpy 1 as numpy.core...
    core = 'numpy._core' if int(np.__version__.split('.')[0]) >= 2 \
        else 'numpy.core'
    assert found == {
        'builtins.getattr', 'collections.OrderedDict', 'collections.Counter',
        'mmengine.logging.history_buffer.HistoryBuffer',
        'torch._utils._rebuild_tensor_v2', 'torch.FloatStorage',
        'numpy.ndarray', 'numpy.dtype', f'{core}.multiarray._reconstruct',
        f'{core}.multiarray.scalar', '_codecs.encode'
    }
    allowed = INFO_GLOBALS | CHECKPOINT_GLOBALS
    assert found - allowed == {'torch.FloatStorage'}


def test_zoo_checkpoint_loads_with_its_history_buffers(zoo_checkpoint):
    """State dict, optimiser and message hub come back; the buffers work.

    The toy model is one 1x1x1 conv (3 -> 3 channels): weight (3, 3, 1, 1,
    1) and bias (3,). 4 samples / batch 2 = 2 iterations, so each loss
    buffer holds 2 values.
    """
    registry = dict(HistoryBuffer._statistics_methods)
    ckpt = load_checkpoint_file(zoo_checkpoint, map_location='cpu')
    assert ckpt['state_dict']['classifier.weight'].shape == (3, 3, 1, 1, 1)
    assert ckpt['meta']['epoch'] == 1 and ckpt['meta']['iter'] == 2
    buffer = ckpt['message_hub']['log_scalars']['train/loss_ce']
    assert isinstance(buffer, HistoryBuffer)
    values, counts = buffer.data
    assert len(values) == 2 and list(counts) == [1, 1]
    assert buffer.mean() == pytest.approx(values.mean())
    assert buffer.statistics('max') == values.max()
    assert dict(HistoryBuffer._statistics_methods) == registry
    assert statistic_names() == {'min', 'max', 'current', 'mean'}


def test_runner_resumes_a_zoo_checkpoint(zoo_checkpoint, tmp_path, capsys):
    """With the hook's loader installed, a Runner resumes it to epoch 2."""
    runner = _runner(
        str(tmp_path),
        2,
        resume=True,
        load_from=zoo_checkpoint,
        custom_hooks=[dict(type='WeightsOnlyCheckpointHook')])
    runner.train()
    assert (runner.epoch, runner.iter) == (2, 4)
    assert osp.isfile(tmp_path / 'epoch_2.pth')


class _Evil:
    """Pickles as ``os.system('touch marker')``."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.system, (f'touch {self.marker}', ))


class _GetAttr:
    """Pickles as ``getattr(obj, name)``; callable so it can be REDUCEd."""

    def __init__(self, obj, name):
        self.obj, self.name = obj, name

    def __call__(self, *args):
        return getattr(self.obj, self.name)(*args)

    def __reduce__(self):
        return (getattr, (self.obj, self.name))


class _Call:
    """Pickles as ``func(*args)``."""

    def __init__(self, func, *args):
        self.func, self.args = func, args

    def __reduce__(self):
        return (self.func, self.args)


def _payloads(marker):
    """Malicious checkpoints by name: each would create ``marker``."""
    array = np.zeros(1)
    return {
        'posix.system': _Evil(marker),
        # getattr on an allowed class other than HistoryBuffer:
        # np.ndarray.tofile(array, marker) writes the file.
        'getattr(ndarray': _Call(_GetAttr(np.ndarray, 'tofile'), array,
                                 str(marker)),
        # getattr of another name of HistoryBuffer, then of the function's
        # globals: the way from an allowed function to any module.
        "getattr(HistoryBuffer, '__init__'":
        _GetAttr(HistoryBuffer, '__init__'),
        "getattr(HistoryBuffer.min, '__globals__'":
        _GetAttr(_GetAttr(HistoryBuffer, 'min'), '__globals__'),
    }


@pytest.mark.parametrize('name', list(_payloads('m')))
def test_malicious_checkpoint_is_refused_by_name(name, tmp_path):
    """Refused naming the file and the global; the payload never ran."""
    marker = tmp_path / 'pwned'
    path = str(tmp_path / 'evil.pth')
    torch.save({'state_dict': {}, 'meta': _payloads(marker)[name]}, path)
    with pytest.raises(UnsafeCheckpointError) as err:
        load_checkpoint_file(path)
    assert f'Refusing to load checkpoint {path}' in str(err.value)
    assert name in str(err.value)
    assert not marker.exists()


def test_state_of_functions_and_statistics_registry_cannot_be_set(tmp_path):
    """BUILD on an allowed function, and a foreign statistics method.

    ``HistoryBuffer.__setstate__`` would register the file's methods
    class-wide; both pickles are refused and nothing changed.
    """
    defaults = HistoryBuffer.min.__defaults__
    registry = dict(HistoryBuffer._statistics_methods)

    class _SetDefaults(_GetAttr):

        def __reduce__(self):
            return (getattr, (HistoryBuffer, 'min'), (None, {
                '__defaults__': (7, )
            }))

    path = str(tmp_path / 'build.pth')
    torch.save({'meta': _SetDefaults(HistoryBuffer, 'min')}, path)
    with pytest.raises(UnsafeCheckpointError, match='BUILD .* function'):
        load_checkpoint_file(path)
    assert HistoryBuffer.min.__defaults__ == defaults

    buffer = HistoryBuffer([1.0], [1])
    buffer.__dict__['statistics_methods'] = {'mean': collections.Counter}
    state = dict(buffer.__dict__)
    buffer.__getstate__ = lambda: state
    path = str(tmp_path / 'registry.pth')
    torch.save({'message_hub': buffer}, path)
    with pytest.raises(UnsafeCheckpointError, match="statistics methods "
                       r"\['mean'\]"):
        load_checkpoint_file(path)
    assert dict(HistoryBuffer._statistics_methods) == registry


def test_legacy_format_and_plain_state_dicts_load(tmp_path):
    """torch's pre-1.6 format and a bare state dict with a Parameter."""
    state = collections.OrderedDict(
        w=torch.arange(6.).reshape(2, 3),
        p=torch.nn.Parameter(torch.ones(2)),
        i=torch.tensor([1, 2], dtype=torch.int64))
    for zipped in (True, False):
        path = str(tmp_path / f'{zipped}.pth')
        torch.save(state, path, _use_new_zipfile_serialization=zipped)
        loaded = load_checkpoint_file(path)
        assert list(loaded) == ['w', 'p', 'i']
        assert torch.equal(loaded['w'], state['w'])
        assert loaded['i'].dtype == torch.int64


@pytest.mark.parametrize('size', [0, 100, -1])
def test_empty_truncated_or_foreign_checkpoint_names_the_file(
        zoo_checkpoint, tmp_path, size):
    """0 bytes, cut to 100 bytes, or a text file: CorruptFileError."""
    path = str(tmp_path / 'bad.pth')
    with open(zoo_checkpoint, 'rb') as f:
        data = f.read()
    with open(path, 'wb') as f:
        f.write(b'not a checkpoint' if size < 0 else data[:size])
    with pytest.raises(CorruptFileError, match=path):
        load_checkpoint_file(path)
    with pytest.raises(FileNotFoundError, match='nope.pth'):
        load_checkpoint_file(str(tmp_path / 'nope.pth'))


def test_info_file_with_a_payload_is_refused(tmp_path):
    """An info pickle calling os.system is refused; nothing ran."""
    marker = tmp_path / 'pwned'
    path = str(tmp_path / 'infos.pkl')
    mmengine.dump(dict(metainfo={}, data_list=[_Evil(marker)]), path)
    with pytest.raises(RefusedGlobalError,
                       match=f'Refusing to load info file {path}: it '
                       'pickles posix.system'):
        load_info_file(path)
    assert not marker.exists()


def test_info_file_content_and_damage(tmp_path):
    """Containers, scalars and numpy arrays load; damage is named."""
    content = dict(
        metainfo=dict(classes=('a', 'b'), version='v'),
        data_list=[
            dict(m=np.eye(4), s=np.float32(1.5), b=b'\x00\xff', n=None,
                 t={1, 2})
        ])
    path = str(tmp_path / 'infos.pkl')
    for protocol in (2, pickle.HIGHEST_PROTOCOL):
        with open(path, 'wb') as f:
            pickle.dump(content, f, protocol=protocol)
        loaded = load_info_file(path)
        entry = loaded['data_list'][0]
        assert np.array_equal(entry['m'], np.eye(4))
        assert entry['s'] == np.float32(1.5) and entry['b'] == b'\x00\xff'
        assert entry['t'] == {1, 2}
    with open(path, 'rb') as f:
        data = f.read()
    with open(path, 'wb') as f:
        f.write(data[:len(data) // 2])
    with pytest.raises(CorruptFileError, match=f'info file {path} is '
                       'truncated or not a pickle'):
        load_info_file(path)
    open(path, 'wb').close()
    with pytest.raises(CorruptFileError, match='is empty'):
        load_info_file(path)


@pytest.mark.skipif(
    not osp.isfile(REAL_INFO),
    reason='../shared/data/nuscenes_real_sample is absent')
def test_mmdet3d_info_file_of_the_real_sample_loads():
    """mmdet3d 1.4's own v2 info file (numpy scalars, bytes) loads."""
    infos = load_info_file(REAL_INFO)
    assert infos['metainfo']['info_version'] == '1.1'
    sample = infos['data_list'][0]
    assert sample['token'] == 'ca9a282c9e77460f8360f564131a8af5'
    assert np.asarray(sample['lidar_points']['lidar2ego']).shape == (4, 4)


def test_importing_the_library_changes_nothing_global():
    """No loader, safe global or file backend is installed on import.

    (torch itself adds its DTensor classes to the safe globals; the old
    loader added numpy's.)
    """
    code = (
        'import torch, projects.occ_common, projects.occ_cyl, '
        'projects.sdg_occ\n'
        'from mmengine.runner.checkpoint import CheckpointLoader\n'
        'from mmengine.fileio.backends.registry_utils import backends\n'
        'from projects.occ_common.fileio.checkpoint_schemes import '
        'is_installed\n'
        'assert not is_installed()\n'
        "assert CheckpointLoader._schemes[''].__module__ == "
        "'mmengine.runner.checkpoint'\n"
        'get = getattr(torch.serialization, "get_safe_globals", list)\n'
        "assert not [g for g in get() if 'numpy' in repr(g)], get()\n"
        "assert 'atomic_local' not in backends\n"
        'WeightsOnly = '
        'projects.occ_common.engine.hooks.WeightsOnlyCheckpointHook\n'
        'WeightsOnly().before_run(None)\n'
        'assert is_installed() and "atomic_local" in backends\n'
        'from projects.occ_common.fileio.checkpoint_schemes import '
        'uninstall_checkpoint_loader\n'
        'uninstall_checkpoint_loader()\n'
        'assert not is_installed()\n'
        "assert CheckpointLoader._schemes[''].__module__ == "
        "'mmengine.runner.checkpoint'\n")
    proc = subprocess.run([sys.executable, '-c', code],
                          cwd=ROOT,
                          capture_output=True,
                          text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]


def test_old_checkpoints_with_tagged_buffers_still_resume(tmp_path):
    """Buffers stored as tagged dicts by the hook's earlier versions."""
    hub = {
        'log_scalars': {
            'train/loss': {
                '__history_buffer__': True,
                'log_history': np.array([0.5, 0.25]),
                'count_history': np.array([1, 1]),
                'max_length': 10
            }
        }
    }
    path = str(tmp_path / 'old.pth')
    torch.save({'message_hub': hub}, path)
    checkpoint = load_checkpoint_file(path)
    WeightsOnlyCheckpointHook().after_load_checkpoint(None, checkpoint)
    buffer = checkpoint['message_hub']['log_scalars']['train/loss']
    assert isinstance(buffer, HistoryBuffer)
    assert buffer.mean() == pytest.approx(0.375)
    assert buffer.max_length == 10


def test_downloaded_checkpoints_are_loaded_restrictedly(zoo_checkpoint,
                                                        tmp_path):
    """http(s):// is served by the restricted loader too once installed
    (a file:// URL stands in for the download here); a malicious download
    is refused like a local file."""
    from mmengine.runner.checkpoint import CheckpointLoader

    from projects.occ_common.fileio import install_checkpoint_loader
    from projects.occ_common.fileio.checkpoint_schemes import _load_from_http
    install_checkpoint_loader()
    for url in ('https://host/zoo.pth', 'http://host/zoo.pth', 'zoo.pth'):
        loader = CheckpointLoader._get_checkpoint_loader(url)
        assert loader.__module__ == \
            'projects.occ_common.fileio.checkpoint_schemes'
    ckpt = _load_from_http(f'file://{zoo_checkpoint}',
                           model_dir=str(tmp_path / 'cache'))
    assert isinstance(ckpt['message_hub']['log_scalars']['train/loss'],
                      HistoryBuffer)
    marker = tmp_path / 'pwned'
    torch.save({'meta': _Evil(marker)}, str(tmp_path / 'evil.pth'))
    with pytest.raises(UnsafeCheckpointError, match='posix.system'):
        _load_from_http(f'file://{tmp_path}/evil.pth',
                        model_dir=str(tmp_path / 'cache'))
    assert not marker.exists()
