"""A checkpoint's strings never run, and a damaged record never loads.

mmengine's ``Runner.resume`` ran ``meta['config']`` of a genuine
checkpoint as Python (``Config.fromstring(..., '.py')``), through
``tools/train.py --resume PATH`` and through a plain ``--resume`` of a
work dir where the file was planted; and torch never compares a zip
record with its CRC-32, so one flipped bit loaded silently.
"""
import os
import os.path as osp
import shutil

import pytest
import torch

from projects.occ_common.analysis.hostile_files import (flip_bit,
                                                        write_config_payload)
from projects.occ_common.fileio import CorruptFileError, load_checkpoint_file
from projects.occ_common.fileio.checkpoint_meta import drop_config_text
from projects.occ_common.testing.tool_logs import REPO_ROOT, load_tool

CONFIG = osp.join(REPO_ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


def _train(work_dir, *argv):
    """tools/train.py on the toy config in this process (~2 s an epoch)."""
    return load_tool('tools/train.py').main(
        [CONFIG, '--work-dir', str(work_dir), *argv])


@pytest.fixture(scope='module')
def toy_checkpoint(tmp_path_factory):
    """epoch_1.pth of the toy config (8 samples, batch 2: 4 iterations)."""
    work = tmp_path_factory.mktemp('toy')
    _train(work, '--cfg-options', 'train_cfg.max_epochs=1')
    return str(work / 'epoch_1.pth')


def test_config_text_is_dropped_and_meta_config_named(tmp_path):
    """Of the three entries, only meta.config (which Runner.resume runs)
    is warned about: every mmengine checkpoint carries the other two."""
    path = str(tmp_path / 'x.pth')
    torch.save(dict(state_dict={}, meta=dict(epoch=1, config='a=1',
                                             cfg='b=2'),
                    message_hub=dict(runtime_info=dict(cfg='c=3', iter=4))),
               path)
    with pytest.warns(UserWarning, match=f'checkpoint {path}: ignoring its '
                      'meta.config'):
        loaded = load_checkpoint_file(path)
    assert loaded['meta'] == dict(epoch=1)
    assert loaded['message_hub'] == dict(runtime_info=dict(iter=4))
    assert drop_config_text(dict(meta=dict(cfg='x')), 'f') == ['meta.cfg']
    assert drop_config_text([1], 'f') == []


@pytest.mark.parametrize('how', ['--resume PATH', 'planted epoch_9.pth'])
def test_resume_never_runs_the_config_text_of_a_checkpoint(
        toy_checkpoint, tmp_path, how):
    """The payload wrote its marker on today's mmengine resume path; now
    the run resumes (epoch 2 is trained) and nothing ran."""
    marker = tmp_path / 'pwned'
    work = tmp_path / 'work'
    if how == '--resume PATH':
        payload = write_config_payload(toy_checkpoint,
                                       str(tmp_path / 'p.pth'), str(marker))
        argv = ['--resume', payload]
    else:
        work.mkdir()
        write_config_payload(toy_checkpoint, str(work / 'epoch_9.pth'),
                             str(marker))
        argv = ['--resume']
    _train(work, *argv, '--cfg-options', 'train_cfg.max_epochs=2')
    assert not marker.exists()
    resumed = load_checkpoint_file(str(work / 'epoch_2.pth'))
    assert (resumed['meta']['epoch'], resumed['meta']['iter']) == (2, 8)


def test_one_flipped_bit_in_a_tensor_is_refused_naming_the_record(
        toy_checkpoint, tmp_path):
    """The toy model's conv weight (3 x 3 float32) is the first tensor
    record, data/0; bit 2 of its byte 0 flipped changes one weight
    (before: loaded without a word). The record's CRC-32 no longer
    matches."""
    path = str(tmp_path / 'flipped.pth')
    shutil.copy(toy_checkpoint, path)
    record = flip_bit(path, 'data/0', bit=2)
    with pytest.raises(CorruptFileError,
                       match=f'checkpoint {path} is damaged: its record '
                       f'{record} does not match its CRC-32'):
        load_checkpoint_file(path)
    # The intact file loads: the check reads every record once more.
    assert load_checkpoint_file(toy_checkpoint)['meta']['epoch'] == 1
    assert os.path.getsize(path) == os.path.getsize(toy_checkpoint)
