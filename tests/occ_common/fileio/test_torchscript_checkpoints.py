"""A TorchScript archive given as a checkpoint runs nothing, at every entry.

``torch.load(..., weights_only=False)`` hands a TorchScript archive to
``torch.jit.load`` whatever unpickler it was given, and that runs the
archive's ``__setstate__``. The payload of
:func:`~projects.occ_common.analysis.hostile_files.write_torchscript_archive`
writes a marker file from its ``__setstate__``; the first test shows that
plain ``torch.load`` does write it, so that every other test, one a
checkpoint entry point of the library, means something: each refuses the
file with an error saying it is TorchScript, and the marker never appears.
"""
import os
import os.path as osp
import shutil

import pytest
import torch
from mmengine.config import Config

from projects.occ_common.analysis.hostile_files import \
    write_torchscript_archive
from projects.occ_common.analysis.tool_runs import load_tool
from projects.occ_common.fileio import (UnsafeCheckpointError,
                                        install_checkpoint_loader,
                                        load_checkpoint_file)

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.dirname(
    osp.abspath(__file__)))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')
REFUSAL = 'it is a TorchScript archive'


@pytest.fixture(scope='module')
def archive(tmp_path_factory):
    """``(path, marker)``: a TorchScript archive writing ``marker``."""
    folder = tmp_path_factory.mktemp('torchscript')
    marker = str(folder / 'marker')
    path = str(folder / 'payload.pth')
    return write_torchscript_archive(path, marker), marker


@pytest.fixture
def payload(archive):
    """The archive's path; afterwards, the marker must not exist (it is
    removed, so that each test finds only its own run)."""
    path, marker = archive
    yield path
    ran = osp.exists(marker)
    if ran:
        os.remove(marker)
    assert not ran, 'the TorchScript payload ran'


def test_plain_torch_load_runs_the_payload(archive, tmp_path):
    """The payload is real: plain torch.load writes the marker."""
    path, _ = archive
    marker = str(tmp_path / 'marker')
    other = str(tmp_path / 'payload.pth')
    write_torchscript_archive(other, marker)
    with pytest.warns(UserWarning, match='TorchScript'):
        torch.load(other, weights_only=False)
    with open(marker, 'rb') as f:
        assert f.read() == b'pwned\n'


def _refused(call, *args, **kwargs):
    """Run ``call``; its error must say the file is TorchScript."""
    with pytest.raises(Exception) as err:  # noqa: B017 - checked below
        call(*args, **kwargs)
    chain, error = [], err.value
    while error is not None:
        chain.append(f'{type(error).__name__}: {error}')
        error = error.__cause__ or error.__context__
    assert any(REFUSAL in text for text in chain), chain


def _toy_model():
    from projects.occ_common.testing.toy_model import ToyOccupancyModel
    return ToyOccupancyModel(in_channels=3, num_classes=3)


def test_load_checkpoint_file(payload):
    """The one function; demo/occ_demo.py, SafeCheckpointHook's read-back
    and the ``pretrained`` entries call it directly."""
    with pytest.raises(UnsafeCheckpointError, match=REFUSAL) as err:
        load_checkpoint_file(payload)
    assert payload in str(err.value)
    assert 'TorchScript is not a checkpoint' in str(err.value)


def test_tools_test(payload, tmp_path):
    """tools/test.py CONFIG CHECKPOINT."""
    _refused(load_tool('tools/test.py').main,
             [CONFIG, payload, '--work-dir', str(tmp_path)])


def test_tools_train_resume_path(payload, tmp_path):
    """tools/train.py --resume CHECKPOINT."""
    _refused(load_tool('tools/train.py').main,
             [CONFIG, '--work-dir', str(tmp_path), '--resume', payload])


def test_tools_train_auto_resume_meets_a_planted_checkpoint(payload,
                                                            tmp_path):
    """tools/train.py --resume: the recovery hook reads epoch_N.pth."""
    shutil.copy(payload, tmp_path / 'epoch_1.pth')
    _refused(load_tool('tools/train.py').main,
             [CONFIG, '--work-dir', str(tmp_path), '--resume'])


def test_load_from(payload, tmp_path):
    """tools/train.py with load_from= (Runner.load_checkpoint)."""
    _refused(load_tool('tools/train.py').main, [
        CONFIG, '--work-dir', str(tmp_path), '--cfg-options',
        f'load_from={payload}'
    ])


def test_init_cfg_pretrained(payload):
    """init_cfg=dict(type='Pretrained', checkpoint=...), and mmengine's
    load_checkpoint (tools/analysis_tools/benchmark.py)."""
    from mmengine.model.weight_init import PretrainedInit
    from mmengine.runner import load_checkpoint
    install_checkpoint_loader()
    _refused(PretrainedInit(checkpoint=payload), _toy_model())
    _refused(load_checkpoint, _toy_model(), payload, map_location='cpu')


def test_pretrained_entry_from_the_hub_cache(payload, tmp_path,
                                             monkeypatch):
    """model.pretrained.<part>.checkpoint='torchvision://resnet50' (the
    configs' own), the file already in torch hub's cache."""
    from projects.occ_common.fileio.hub_cache import TORCHVISION_URLS
    from projects.occ_common.models.pretrained import (check_entries,
                                                       load_pretrained)
    monkeypatch.setattr(torch.hub, '_hub_dir', str(tmp_path))
    (tmp_path / 'checkpoints').mkdir()
    shutil.copy(
        payload, tmp_path / 'checkpoints' /
        osp.basename(TORCHVISION_URLS['resnet50']))
    entry = check_entries(
        dict(part=dict(module='classifier',
                       checkpoint='torchvision://resnet50',
                       style=None)))['part']
    _refused(load_pretrained, _toy_model().classifier, 'part', entry)


@pytest.mark.parametrize('url', [
    'https://host/zoo.pth', 'open-mmlab://detectron2/resnet50_caffe',
    'mmcls://vgg11'
])
def test_mmengine_url_schemes_from_the_hub_cache(payload, url, tmp_path,
                                                 monkeypatch):
    """mmengine's CheckpointLoader of URLs and zoo names, the file already
    in the hub cache (load_from=URL, init_cfg with a URL)."""
    from mmengine.runner.checkpoint import (CheckpointLoader,
                                            get_external_models,
                                            get_mmcls_models)
    monkeypatch.setattr(torch.hub, '_hub_dir', str(tmp_path))
    scheme, name = url.split('://')
    known = dict(
        mmcls=get_mmcls_models(), https={name: url}).get(
            scheme, get_external_models())
    (tmp_path / 'checkpoints').mkdir()
    shutil.copy(payload,
                tmp_path / 'checkpoints' / osp.basename(known[name]))
    install_checkpoint_loader()
    _refused(CheckpointLoader.load_checkpoint, url, map_location='cpu')


def test_visualize_occ(payload, tmp_path):
    """tools/misc/visualize_occ.py --config --checkpoint."""
    _refused(load_tool('tools/misc/visualize_occ.py').main, [
        '--config', CONFIG, '--checkpoint', payload, '--out',
        str(tmp_path / 'x.png')
    ])


def test_demo(payload):
    """demo/occ_demo.py's init_model."""
    _refused(load_tool('demo/occ_demo.py').init_model,
             Config.fromfile(CONFIG), payload, 'cpu')


def test_every_mmengine_scheme_is_served_by_the_restricted_loader():
    """A scheme mmengine adds would load with plain torch.load."""
    from mmengine.runner.checkpoint import CheckpointLoader

    from projects.occ_common.fileio.checkpoint_schemes import is_installed
    install_checkpoint_loader()
    assert is_installed()
    for prefix, loader in CheckpointLoader._schemes.items():
        assert loader.__module__ == \
            'projects.occ_common.fileio.checkpoint_schemes', prefix


def test_only_torch_save_archives_reach_torch_load(tmp_path):
    """A zip archive with other records than torch.save writes (here a
    TorchScript-free one, whose data.pkl torch would unpickle) is refused
    naming a record; a torch.save archive loads."""
    import pickle
    import zipfile

    from projects.occ_common.fileio import CorruptFileError
    path = str(tmp_path / 'odd.pth')
    with zipfile.ZipFile(path, 'w') as archive:
        archive.writestr('archive/data.pkl', pickle.dumps({}, protocol=2))
        archive.writestr('archive/readme.txt', 'hello')
        archive.writestr('archive/version', '3\n')
    with pytest.raises(CorruptFileError, match='records torch.save does '
                       'not write: readme.txt'):
        load_checkpoint_file(path)
    torch.save({'w': torch.ones(1)}, path)
    assert load_checkpoint_file(path)['w'].item() == 1
