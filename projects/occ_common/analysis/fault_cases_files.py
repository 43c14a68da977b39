"""Fault-matrix cases: hostile and damaged checkpoints and info files,
through every loader and every tool that loads one (see
:mod:`.fault_cases`)."""
import os
import os.path as osp
import pickle
import shutil
from typing import List

import numpy as np
import torch

from . import hostile_files as hostile
from .fault_cases import (CLEAR, CONFIG, HANDLED, REAL_SAMPLE, Case, Silent,
                          tool)

REAL_INFO = osp.join(REAL_SAMPLE, 'n015-2018-07-24-11-22-45+0800.pkl')
_ZOO = 'https://download.openmmlab.com/pretrain/third_party/' \
    'resnet50_msra-5891d200.pth'
#: A tiny config of each kind the exporter and the demo take.
_TINY_OCC_CYL = osp.join('configs', 'occ_cyl',
                         'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')


def _load_checkpoint_file(path):
    from ..fileio import load_checkpoint_file
    return load_checkpoint_file(path)


def _load_info_file(path):
    from ..fileio import load_info_file
    return load_info_file(path)


def _torchscript(name='payload.pth'):
    return lambda folder, marker: hostile.write_torchscript_archive(
        osp.join(folder, name), marker)


def _in_hub_cache(make, url):
    """``make``'s file, as torch hub's cached download of ``url``."""

    def made(folder, marker):
        cache = osp.join(folder, 'hub', 'checkpoints')
        os.makedirs(cache)
        return shutil.move(
            make(folder, marker), osp.join(cache, osp.basename(url)))

    return made


def _mmengine(url):
    """Load ``url`` with mmengine's CheckpointLoader (load_from=URL),
    torch hub's cache being the case's folder."""

    def load(path):
        torch.hub.set_dir(osp.dirname(osp.dirname(path)))
        from mmengine.runner.checkpoint import CheckpointLoader

        from ..fileio import install_checkpoint_loader
        install_checkpoint_loader()
        return CheckpointLoader.load_checkpoint(url or path, 'cpu')

    return load


def _resume(path):
    """tools/train.py --resume: the recovery hook reads the work dir's
    epoch_N.pth."""
    from ..engine.hooks.checkpoint_recovery_hook import repair_work_dir
    return repair_work_dir(osp.dirname(path))


def _sdg_real_sample(path):
    """benchmark_sdg.py --real-sample: the folder's one info file."""
    from .tool_runs import load_tool
    return load_tool('tools/analysis_tools/benchmark_sdg.py').real_sample(
        None, osp.dirname(path))


def _forged(kind, forgery):
    name = 'infos.pkl' if kind == 'info file' else 'x.pth'
    return lambda folder, marker: hostile.write_forged_array(
        osp.join(folder, name), kind, forgery)


def _os_system(kind, name):
    return lambda folder, marker: hostile.write_os_system(
        osp.join(folder, name), kind, marker)


def _damaged(make, size):
    """``make``'s file cut to ``size`` bytes."""

    def made(folder, marker):
        path = make(folder, marker)
        with open(path, 'rb+') as f:
            f.truncate(size)
        return path

    return made


def _valid_checkpoint(zipped=True):

    def made(folder, marker):
        path = osp.join(folder, 'valid.pth')
        torch.save(dict(state_dict=dict(w=torch.ones(2)),
                        meta=dict(a=np.arange(3, dtype='>f4'),
                                  s=np.float64(1), u=np.array(['ab']))),
                   path, _use_new_zipfile_serialization=zipped)
        return path

    return made


def _flipped_bit(folder, marker):
    """A checkpoint of 1000 weights 0..999, bit 2 of its first byte
    flipped (weight 0 becomes 2 ** -148 as float32 bits)."""
    path = osp.join(folder, 'flipped.pth')
    torch.save(dict(state_dict=dict(w=torch.arange(1000.))), path)
    hostile.flip_bit(path, 'data/0')
    return path


def _load_unchanged(path):
    """Load; a checkpoint whose weights are not 0..999 is a silent
    change."""
    from ..fileio import load_checkpoint_file
    weights = load_checkpoint_file(path)['state_dict']['w']
    if not torch.equal(weights, torch.arange(1000.)):
        raise Silent('a damaged weight loaded without a word')
    return weights


def _valid_info(folder, marker):
    path = osp.join(folder, 'infos.pkl')
    with open(path, 'wb') as f:
        pickle.dump(dict(metainfo={}, data_list=[dict(
            m=np.eye(4), s=np.float32(1), t='token')]), f, protocol=2)
    return path


def _foreign_zip(folder, marker):
    import zipfile
    path = osp.join(folder, 'not_a_checkpoint.pth')
    with zipfile.ZipFile(path, 'w') as archive:
        archive.writestr('archive/data.pkl', pickle.dumps({}))
        archive.writestr('archive/readme.txt', 'hello')
        archive.writestr('archive/version', '3\n')
    return path


def _rng_checkpoint(folder, marker):
    """A checkpoint of RandomStateHook (ByteTensor, numpy, Python)."""
    from ..engine.hooks.random_state_hook import get_random_state
    path = osp.join(folder, 'rng.pth')
    torch.save(dict(meta={}, rng_state=dict(
        world_size=1, ranks=[get_random_state()])), path)
    return path


def _other_model(folder, marker):
    """The toy model's checkpoint with another head, as another model's."""
    path = osp.join(folder, 'other_model.pth')
    torch.save(dict(meta={}, state_dict={'head.weight': torch.ones(3, 3)}),
               path)
    return path


def _pretrained(path):
    """A detector's ``pretrained`` entry naming the file, for a conv."""
    from ..models.pretrained import check_entries, load_pretrained
    entry = check_entries(dict(part=dict(module='part', checkpoint=path)))
    return load_pretrained(torch.nn.Conv2d(3, 4, 1), 'part', entry['part'])


def _real_info(folder, marker):
    """A copy of the real key frame's mmdet3d info file."""
    return shutil.copy(REAL_INFO, osp.join(folder, 'infos.pkl'))


def _torchscript_beside_real_info(folder, marker):
    """A TorchScript archive as the checkpoint, the real sample's info
    file beside it (its paths relative to the real sample's folder)."""
    _real_info(folder, marker)
    return hostile.write_torchscript_archive(
        osp.join(folder, 'payload.pth'), marker)


def _demo(path):
    """demo/occ_demo.py on the tiny OccCylindrical, the real sample."""
    from .tool_runs import load_tool
    folder = osp.dirname(path)
    return load_tool('demo/occ_demo.py').main([
        _TINY_OCC_CYL, path, osp.join(folder, 'infos.pkl'), '--data-root',
        REAL_SAMPLE, '--out-dir', osp.join(folder, 'out'), '--device', 'cpu'
    ])


_MMENGINE_CASES = [
    Case('TorchScript checkpoint: load_from (mmengine, local)', CLEAR,
         _torchscript(), _mmengine(None)),
    Case('TorchScript checkpoint in the hub cache: https:// URL', CLEAR,
         _in_hub_cache(_torchscript(), _ZOO), _mmengine(_ZOO)),
    Case('TorchScript checkpoint in the hub cache: open-mmlab://', CLEAR,
         _in_hub_cache(_torchscript(), _ZOO),
         _mmengine('open-mmlab://detectron2/resnet50_caffe')),
    Case('os.system checkpoint in the hub cache: open-mmlab://', CLEAR,
         _in_hub_cache(_os_system('checkpoint', 'x.pth'), _ZOO),
         _mmengine('open-mmlab://detectron2/resnet50_caffe')),
]

#: Checkpoints and info files through the loaders and the tools.
FILE_CASES: List[Case] = [
    Case('TorchScript checkpoint: load_checkpoint_file', CLEAR,
         _torchscript(), _load_checkpoint_file,
         names=lambda path: [osp.basename(path), 'TorchScript'],
         guards=('TorchScript refused', )),
    Case('TorchScript checkpoint: tools/test.py', CLEAR, _torchscript(),
         tool('tools/test.py', CONFIG, '{path}', '--work-dir', '{work}')),
    Case('TorchScript checkpoint: tools/train.py --resume PATH', CLEAR,
         _torchscript(),
         tool('tools/train.py', CONFIG, '--work-dir', '{work}', '--resume',
              '{path}')),
    Case('TorchScript checkpoint planted as epoch_1.pth: --resume', CLEAR,
         _torchscript('epoch_1.pth'), _resume),
    *_MMENGINE_CASES,
    Case('TorchScript checkpoint: tools/misc/visualize_occ.py', CLEAR,
         _torchscript(),
         tool('tools/misc/visualize_occ.py', '--config', CONFIG,
              '--checkpoint', '{path}', '--out', '{work}.png'),
         guards=('init_model loads restricted', )),
    Case('TorchScript checkpoint: tools/deployment/export_onnx.py', CLEAR,
         _torchscript(),
         tool('tools/deployment/export_onnx.py', _TINY_OCC_CYL, '{path}',
              '--out', '{work}.onnx'),
         guards=('init_model loads restricted', )),
    Case('TorchScript checkpoint: a detector\'s pretrained weights', CLEAR,
         _torchscript(), _pretrained,
         guards=('pretrained loads restricted', )),
    Case('os.system checkpoint: load_checkpoint_file', CLEAR,
         _os_system('checkpoint', 'x.pth'), _load_checkpoint_file,
         guards=('restricted unpickler', )),
    Case('os.system checkpoint: a detector\'s pretrained weights', CLEAR,
         _os_system('checkpoint', 'x.pth'), _pretrained),
    *(Case(f'{forgery}: {kind}', CLEAR, _forged(kind, forgery),
           _load_checkpoint_file if kind == 'checkpoint' else
           _load_info_file)
      for forgery in hostile.FORGERIES
      for kind in ('checkpoint', 'info file')),
    Case('os.system info file: load_info_file', CLEAR,
         _os_system('info file', 'infos.pkl'), _load_info_file),
    Case('os.system info file: benchmark_sdg.py --real-sample', CLEAR,
         _os_system('info file', 'infos.pkl'), _sdg_real_sample),
    Case('truncated checkpoint', CLEAR, _damaged(_valid_checkpoint(), 200),
         _load_checkpoint_file),
    Case('empty checkpoint', CLEAR, _damaged(_valid_checkpoint(), 0),
         _load_checkpoint_file),
    Case('checkpoint with one flipped bit', CLEAR, _flipped_bit,
         _load_unchanged, guards=('zip CRC',)),
    Case('zip archive that is no checkpoint', CLEAR, _foreign_zip,
         _load_checkpoint_file),
    Case('truncated info file', CLEAR, _damaged(_valid_info, 40),
         _load_info_file),
    Case('valid checkpoint with numpy objects', HANDLED,
         _valid_checkpoint(), _load_checkpoint_file),
    Case('valid legacy-format checkpoint', HANDLED,
         _valid_checkpoint(False), _load_checkpoint_file),
    Case('valid info file with numpy objects', HANDLED, _valid_info,
         _load_info_file),
    Case('checkpoint with a random state (ByteTensor)', HANDLED,
         _rng_checkpoint, _load_checkpoint_file),
    Case('checkpoint of another model: tools/train.py load_from=', CLEAR,
         _other_model,
         tool('tools/train.py', CONFIG, '--work-dir', '{work}',
              '--cfg-options', 'load_from={path}')),
    Case('checkpoint of another model: tools/train.py --resume PATH',
         CLEAR, _other_model,
         tool('tools/train.py', CONFIG, '--work-dir', '{work}', '--resume',
              '{path}'), guards=('resume checks the model', )),
    Case('checkpoint of another model: tools/misc/visualize_occ.py', CLEAR,
         _other_model,
         tool('tools/misc/visualize_occ.py', '--config', CONFIG,
              '--checkpoint', '{path}', '--out', '{work}.png'),
         guards=('init_model checks weights', )),
    Case('checkpoint of another model: tools/analysis_tools/benchmark.py',
         CLEAR, _other_model,
         tool('tools/analysis_tools/benchmark.py', CONFIG, '{path}',
              '--device', 'cpu', '--runs', '1', '--warmup', '0',
              '--matmul-size', '0'),
         guards=('init_model checks weights', )),
]
if osp.isfile(REAL_INFO):
    FILE_CASES += [
        Case('mmdet3d info file of the real sample', HANDLED, _real_info,
             _load_info_file),
        Case('TorchScript checkpoint: demo/occ_demo.py', CLEAR,
             _torchscript_beside_real_info, _demo,
             guards=('init_model loads restricted', )),
    ]

__all__ = ['FILE_CASES', 'REAL_INFO']
