"""Fault matrix of the checkpoint and pickle loaders, one child a case.

Every case writes a file as users meet it (a download, a file planted in a
work dir or in torch hub's cache, a damaged copy, a valid file) and feeds
it to one entry point of the library in a forked child process. The
outcome is classed:

* ``clear error``: refused, and the message names the file;
* ``handled``: loaded (a valid file);
* ``unclear error``: an error that does not name the file;
* ``code execution``: the payload's marker file appeared;
* ``segfault``: the child died of a signal;
* ``hang``: it ran past ``--timeout``.

Usage::

    python tools/analysis_tools/fault_matrix.py [--only TEXT] [--timeout S]

prints a line a case and the count of each class, and exits with status 1
if a case's class is not the one :data:`CASES` expects. A case is a
:class:`Case`: its name, the expected class (``'clear error'`` or
``'handled'``), ``make(folder, marker)`` writing its file under ``folder``
(in the parent) and returning its path, and ``load(path)`` loading it
through the entry point (in the child). The hostile files come from
:mod:`projects.occ_common.analysis.hostile_files`.
"""
import argparse
import collections
import glob
import multiprocessing
import os
import os.path as osp
import pickle
import shutil
import tempfile
from typing import Any, Callable, List, NamedTuple

import numpy as np
import torch

from projects.occ_common.analysis import hostile_files as hostile
from projects.occ_common.fileio import (install_checkpoint_loader,
                                        load_checkpoint_file, load_info_file)

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')
REAL_INFO = osp.join(ROOT, '..', 'shared', 'data', 'nuscenes_real_sample',
                     'n015-2018-07-24-11-22-45+0800.pkl')


class Case(NamedTuple):
    """One file fed to one entry point (see the module docstring)."""
    name: str
    expected: str
    make: Callable[[str, str], str]
    load: Callable[[str], Any]


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
        install_checkpoint_loader()
        from mmengine.runner.checkpoint import CheckpointLoader
        return CheckpointLoader.load_checkpoint(url or path, 'cpu')

    return load


def _resume(path):
    """tools/train.py --resume: the recovery hook reads the work dir's
    epoch_N.pth."""
    from projects.occ_common.engine.hooks.checkpoint_recovery_hook import \
        repair_work_dir
    return repair_work_dir(osp.dirname(path))


def _tool(script, *argv):
    """``main`` of a tool, ``{path}`` in ``argv`` replaced."""

    def load(path):
        from projects.occ_common.analysis.tool_runs import load_tool
        work = osp.join(osp.dirname(path), 'work')
        return load_tool(script).main(
            [a.format(path=path, work=work) for a in argv])

    return load


def _sdg_real_sample(path):
    """benchmark_sdg.py --real-sample: the folder's one info file."""
    from projects.occ_common.analysis.tool_runs import load_tool
    tool = load_tool('tools/analysis_tools/benchmark_sdg.py')
    return tool.real_sample(None, osp.dirname(path))


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


def _copied_work_dir(folder, marker):
    """epoch_1..3.pth as ``cp`` leaves them (epoch_1.pth copied last: the
    newest file time), the pointer on epoch_3.pth."""
    for step in (1, 2, 3):
        path = osp.join(folder, f'epoch_{step}.pth')
        torch.save(dict(meta=dict(epoch=step, iter=step), state_dict={}),
                   path)
        os.utime(path, (4e6 - step * 1e6, ) * 2)
    with open(osp.join(folder, 'last_checkpoint'), 'w') as f:
        f.write(osp.join(folder, 'epoch_3.pth'))
    return osp.join(folder, 'epoch_1.pth')


def _auto_resume_target(path):
    """tools/train.py --resume in the copied work dir: the pointer must
    still name the latest step (else: data loss, an error naming none)."""
    from projects.occ_common.engine.hooks.checkpoint_recovery_hook import \
        repair_work_dir
    folder = osp.dirname(path)
    repair_work_dir(folder)
    with open(osp.join(folder, 'last_checkpoint')) as f:
        target = f.read()
    if not target.endswith('epoch_3.pth'):
        raise RuntimeError('--resume went back in time')
    return target


def _resume_before_later_steps(path):
    """tools/train.py --resume epoch_1.pth next to epoch_2/3.pth."""
    from projects.occ_common.engine.hooks.checkpoint_recovery_hook import \
        check_no_later_checkpoint
    return check_no_later_checkpoint(osp.dirname(path), path)


def _rng_checkpoint(folder, marker):
    """A checkpoint of RandomStateHook (ByteTensor, numpy, Python)."""
    from projects.occ_common.engine.hooks.random_state_hook import \
        get_random_state
    path = osp.join(folder, 'rng.pth')
    torch.save(dict(meta={}, rng_state=dict(
        world_size=1, ranks=[get_random_state()])), path)
    return path


def _points(layout):
    """A LiDAR key frame of nuScenes points written as ``layout``."""
    rows = np.array([[12.345, -3.21, 0.875, 17, 3], [-40.5, 7.1, -1.6, 2, 31]])

    def made(folder, marker):
        path = osp.join(folder, 'key.pcd.bin')
        if layout == 'float64':
            rows.tofile(path)
        elif layout == '4 values a point':
            np.tile(rows, (3, 1))[:5, :4].astype(np.float32).tofile(path)
        else:  # all NaN
            np.full((2, 5), np.nan, np.float32).tofile(path)
        return path

    return made


def _load_points(path):
    """LoadOccPointsFromFile; an all-NaN frame must be dropped with a
    warning naming the file (else a silent drop: an error naming none)."""
    import warnings

    import projects.occ_common.transforms  # noqa: F401  (registers)
    from projects.occ_common.transforms.points_loading import \
        LoadOccPointsFromFile
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        points = load(dict(lidar_points=dict(lidar_path=path)))['points']
    if not any(path in str(w.message) for w in caught) and len(points) < 5:
        raise RuntimeError('points dropped without a word')
    return points


def _info(edit):
    """An info file of the converter's layout, changed by ``edit``."""

    def made(folder, marker):
        from projects.occ_common.datasets.info_format import (
            INFO_VERSION, REQUIRED_SAMPLE_KEYS)
        entries = [{key: None for key in REQUIRED_SAMPLE_KEYS}
                   for _ in range(2)]
        for i, entry in enumerate(entries):
            entry['token'] = f'token{i}'
        infos = dict(metainfo=dict(info_version=INFO_VERSION),
                     data_list=entries)
        edit(infos)
        path = osp.join(folder, 'infos.pkl')
        with open(path, 'wb') as f:
            pickle.dump(infos, f, protocol=2)
        return path

    return made


def _check_info(path):
    """What NuScenesOccDataset checks first."""
    from projects.occ_common.datasets.info_format import check_info_file
    return check_info_file(load_info_file(path), path)


def _bool_semantics(folder, marker):
    path = osp.join(folder, 'labels.npz')
    grid = np.zeros((200, 200, 16), np.uint8)
    np.savez(path, semantics=grid.astype(bool), mask_lidar=grid,
             mask_camera=grid)
    return path


def _load_occ3d(path):
    import projects.occ_common.transforms  # noqa: F401  (registers)
    from projects.occ_common.transforms.loading import LoadOccupancyGT
    return LoadOccupancyGT('occ3d')(dict(occ_path=path))


def _other_model(folder, marker):
    """The toy model's checkpoint with another head, as another model's."""
    path = osp.join(folder, 'other_model.pth')
    torch.save(dict(meta={}, state_dict={'head.weight': torch.ones(3, 3)}),
               path)
    return path


_ZOO = 'https://download.openmmlab.com/pretrain/third_party/' \
    'resnet50_msra-5891d200.pth'
_CLEAR, _HANDLED = 'clear error', 'handled'

#: The cases: (name, expected class, make, load).
CASES: List[Case] = [
    Case('TorchScript checkpoint: load_checkpoint_file', _CLEAR,
         _torchscript(), load_checkpoint_file),
    Case('TorchScript checkpoint: tools/test.py', _CLEAR, _torchscript(),
         _tool('tools/test.py', CONFIG, '{path}', '--work-dir', '{work}')),
    Case('TorchScript checkpoint: tools/train.py --resume PATH', _CLEAR,
         _torchscript(),
         _tool('tools/train.py', CONFIG, '--work-dir', '{work}', '--resume',
               '{path}')),
    Case('TorchScript checkpoint planted as epoch_1.pth: --resume', _CLEAR,
         _torchscript('epoch_1.pth'), _resume),
    Case('TorchScript checkpoint: load_from (mmengine, local)', _CLEAR,
         _torchscript(), _mmengine(None)),
    Case('TorchScript checkpoint in the hub cache: https:// URL', _CLEAR,
         _in_hub_cache(_torchscript(), _ZOO), _mmengine(_ZOO)),
    Case('TorchScript checkpoint in the hub cache: open-mmlab://', _CLEAR,
         _in_hub_cache(_torchscript(), _ZOO),
         _mmengine('open-mmlab://detectron2/resnet50_caffe')),
    Case('TorchScript checkpoint: tools/misc/visualize_occ.py', _CLEAR,
         _torchscript(),
         _tool('tools/misc/visualize_occ.py', '--config', CONFIG,
               '--checkpoint', '{path}', '--out', '{work}.png')),
    Case('os.system checkpoint: load_checkpoint_file', _CLEAR,
         _os_system('checkpoint', 'x.pth'), load_checkpoint_file),
    Case('os.system checkpoint in the hub cache: open-mmlab://', _CLEAR,
         _in_hub_cache(_os_system('checkpoint', 'x.pth'), _ZOO),
         _mmengine('open-mmlab://detectron2/resnet50_caffe')),
    *(Case(f'{forgery}: {kind}', _CLEAR, _forged(kind, forgery),
           load_checkpoint_file if kind == 'checkpoint' else load_info_file)
      for forgery in hostile.FORGERIES
      for kind in ('checkpoint', 'info file')),
    Case('os.system info file: load_info_file', _CLEAR,
         _os_system('info file', 'infos.pkl'), load_info_file),
    Case('os.system info file: benchmark_sdg.py --real-sample', _CLEAR,
         _os_system('info file', 'infos.pkl'), _sdg_real_sample),
    Case('truncated checkpoint', _CLEAR, _damaged(_valid_checkpoint(), 200),
         load_checkpoint_file),
    Case('empty checkpoint', _CLEAR, _damaged(_valid_checkpoint(), 0),
         load_checkpoint_file),
    Case('zip archive that is no checkpoint', _CLEAR, _foreign_zip,
         load_checkpoint_file),
    Case('truncated info file', _CLEAR, _damaged(_valid_info, 40),
         load_info_file),
    Case('valid checkpoint with numpy objects', _HANDLED,
         _valid_checkpoint(), load_checkpoint_file),
    Case('valid legacy-format checkpoint', _HANDLED,
         _valid_checkpoint(False), load_checkpoint_file),
    Case('valid info file with numpy objects', _HANDLED, _valid_info,
         load_info_file),
    # Added 2026-11-28 (9e05221): data loss, silent input, unclear errors.
    Case('work dir copied with cp (file times reversed): --resume',
         _HANDLED, _copied_work_dir, _auto_resume_target),
    Case('--resume epoch_1.pth next to epoch_2/3.pth', _CLEAR,
         _copied_work_dir, _resume_before_later_steps),
    Case('checkpoint with a random state (ByteTensor)', _HANDLED,
         _rng_checkpoint, load_checkpoint_file),
    *(Case(f'LiDAR key frame of {layout}', expected, _points(layout),
           _load_points)
      for layout, expected in (('float64', _CLEAR),
                               ('4 values a point', _CLEAR),
                               ('all NaN', _HANDLED))),
    Case('info file listing a sample twice', _CLEAR,
         _info(lambda i: i['data_list'].append(i['data_list'][0])),
         _check_info),
    Case('info file with a sample that is not a dict', _CLEAR,
         _info(lambda i: i['data_list'].append(['token2'])), _check_info),
    Case('info file whose metainfo is a list', _CLEAR,
         _info(lambda i: i.update(metainfo=list(i['metainfo'].items()))),
         _check_info),
    Case('boolean Occ3D semantics', _CLEAR, _bool_semantics, _load_occ3d),
    Case('checkpoint of another model: tools/train.py load_from=', _CLEAR,
         _other_model,
         _tool('tools/train.py', CONFIG, '--work-dir', '{work}',
               '--cfg-options', 'load_from={path}')),
    Case('checkpoint of another model: tools/train.py --resume PATH',
         _CLEAR, _other_model,
         _tool('tools/train.py', CONFIG, '--work-dir', '{work}', '--resume',
               '{path}')),
    Case('checkpoint of another model: tools/misc/visualize_occ.py', _CLEAR,
         _other_model,
         _tool('tools/misc/visualize_occ.py', '--config', CONFIG,
               '--checkpoint', '{path}', '--out', '{work}.png')),
]
if osp.isfile(REAL_INFO):
    CASES.append(
        Case('mmdet3d info file of the real sample', _HANDLED,
             lambda folder, marker: shutil.copy(REAL_INFO, folder),
             load_info_file))


def _child(load, path, conn) -> None:
    """Load in the child; send ``OK`` or the error."""
    try:
        loaded = load(path)
        repr(loaded)  # reading a forged array is what crashes
        conn.send('OK')
    except BaseException as err:  # noqa: BLE001 - SystemExit included
        conn.send(f'{type(err).__name__}: {err}')


def run_case(case: Case, timeout: float) -> str:
    """The class of ``case``'s outcome (see the module docstring)."""
    context = multiprocessing.get_context('fork')
    with tempfile.TemporaryDirectory() as folder:
        marker = osp.join(folder, 'marker')
        path = case.make(folder, marker)
        receive, send = context.Pipe(duplex=False)
        child = context.Process(target=_child, args=(case.load, path, send))
        child.start()
        child.join(timeout)
        if child.is_alive():
            child.kill()
            child.join()
            return 'hang'
        if osp.exists(marker) or glob.glob(osp.join(glob.escape(folder), '**', 'marker'),
                                           recursive=True):
            return 'code execution'
        if child.exitcode != 0:
            return 'segfault' if child.exitcode < 0 else 'unclear error'
        message = receive.recv() if receive.poll() else ''
        if message == 'OK':
            return 'handled'
        named = osp.basename(path) in message
        return 'clear error' if named else 'unclear error'


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--only', help='run the cases whose name has TEXT')
    parser.add_argument(
        '--timeout', type=float, default=120, help='seconds a case')
    return parser.parse_args(argv)


def main(argv=None) -> dict:
    """Run the cases; print them and the count of each class.

    Returns:
        dict: Class -> count.
    """
    args = parse_args(argv)
    counts, wrong = collections.Counter(), []
    for case in CASES:
        if args.only and args.only not in case.name:
            continue
        outcome = run_case(case, args.timeout)
        counts[outcome] += 1
        flag = '' if outcome == case.expected else \
            f'   <- expected {case.expected}'
        print(f'{outcome:15s} {case.name}{flag}', flush=True)
        if flag:
            wrong.append(case.name)
    print('counts: ' + ', '.join(f'{n} {k}' for k, n in counts.items()))
    if wrong:
        raise SystemExit(f'{len(wrong)} case(s) not as expected')
    return dict(counts)


if __name__ == '__main__':
    main()
