"""SIGKILL a real tiny config mid-training, --resume, and end bit for bit
where an uninterrupted run ends.

The tiny SDG-Fusion trains on the converted tiny world (one scene of two
key frames, train = val) with its random augmentations on: per-view image
resize / crop / flip / rotation (MultiViewImageAug) and BEV flips
(OccBEVAug). Before, those drew from the global ``np.random``, whose state
a checkpoint does not hold: a resumed run augmented differently and 229
of its 317 tensors differed from an uninterrupted run. Now each sample's
augmentation is seeded by (seed, epoch, index), so the resumed run
repeats the uninterrupted one exactly (that dataloader workers load the
same samples is checked in tests/occ_common/datasets/
test_augmentation_seed.py; here all runs load in the main process to
keep the test short).

``randomness.deterministic=True``: on CPU the backward of indexing
accumulates in thread order otherwise, so that even two uninterrupted runs
of this config differ in about 200 tensors by float rounding (measured
with 2 threads; the first step's gradients already differ between two
processes, never within one).

OccCylindrical adds random layers: DropPath in its TPV Swin encoder draws
from torch's global generator, whose state a checkpoint did not hold, so a
resume from epoch 1 drew other masks from its first iteration (284 of 417
tensors differed after one more iteration). ``RandomStateHook`` now saves
and restores that state. Its test resumes in this process from the
uninterrupted run's epoch_1.pth (the kill itself is what the SDG-Fusion
test covers) on one sample, so that two epochs are two iterations.
"""
import os
import os.path as osp
import shutil
import signal
import subprocess
import sys
import time
import uuid

import pytest
import torch
from mmengine.config import Config
from mmengine.runner import Runner

from projects.occ_common.fileio import load_checkpoint_file

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'configs', 'sdg_occ',
                  'sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py')
EPOCHS = 2
ITERS_PER_EPOCH = 2  # 2 samples, batch 1


def _train_cmd(work_dir, data_root, *extra):
    options = [
        # No validation (the loop would run it after the last epoch).
        f'train_cfg.max_epochs={EPOCHS}', 'train_cfg.val_begin=100',
        'default_hooks.checkpoint.interval=1', 'randomness.seed=0',
        'randomness.deterministic=True',
    ] + [
        f'{split}_dataloader.dataset.data_root={data_root}'
        for split in ('train', 'val', 'test')
    ]
    return [
        sys.executable,
        osp.join(ROOT, 'tools', 'train.py'), CONFIG, '--work-dir',
        str(work_dir), *extra, '--cfg-options', *options
    ]


#: The children train on the CPU even where a GPU is: the exactness this
#: test asks for is the CPU's (CUDA kernels need not repeat their float
#: rounding, and deterministic mode there needs CUBLAS_WORKSPACE_CONFIG).
CPU_ONLY = dict(os.environ, CUDA_VISIBLE_DEVICES='')


def _run(cmd):
    proc = subprocess.run(cmd, cwd=ROOT, env=CPU_ONLY, capture_output=True,
                          text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout + proc.stderr


def _state_dict(path):
    return load_checkpoint_file(path, map_location='cpu')['state_dict']


@pytest.mark.slow
def test_sigkill_then_resume_matches_an_uninterrupted_run(
        converted_tiny_world, tmp_path):
    """Killed as soon as epoch_1.pth exists; --resume from it (found
    through the pointer or, if the kill came first, without it); every
    tensor of epoch_2.pth equals the uninterrupted run's."""
    data_root = converted_tiny_world.rstrip('/') + '/'
    straight = tmp_path / 'straight'
    _run(_train_cmd(straight, data_root))

    killed = tmp_path / 'killed'
    log = open(tmp_path / 'killed.log', 'w')
    child = subprocess.Popen(_train_cmd(killed, data_root),
                             cwd=ROOT, env=CPU_ONLY, stdout=log,
                             stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 600
    try:
        while not osp.exists(killed / 'epoch_1.pth'):
            assert child.poll() is None, 'training ended before the kill'
            assert time.monotonic() < deadline, 'no checkpoint in 600 s'
            time.sleep(0.005)
        still_running = child.poll() is None
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.wait(timeout=60)
        log.close()
    assert still_running and child.returncode == -signal.SIGKILL
    assert not osp.exists(killed / f'epoch_{EPOCHS}.pth')

    output = _run(_train_cmd(killed, data_root, '--resume'))
    assert f'resumed epoch: 1, iter: {ITERS_PER_EPOCH}' in output

    final = f'epoch_{EPOCHS}.pth'
    expected = _state_dict(straight / final)
    resumed = _state_dict(killed / final)
    assert list(resumed) == list(expected)
    differ = [name for name, tensor in expected.items()
              if not torch.equal(resumed[name], tensor)]
    assert differ == [], f'{len(differ)} of {len(expected)} differ'


OCCCYL = osp.join(ROOT, 'configs', 'occ_cyl',
                  'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')


def _occcyl_cfg(work_dir, data_root, resume_from=None):
    cfg = Config.fromfile(OCCCYL)
    # No yapf formatting of the config text: ~1.7 s each of the 11 times
    # the two Runners log, dump or save it (mmengine 0.10.7's fromfile
    # ignores its format_python_code argument).
    object.__setattr__(cfg, '_format_python_code', False)
    cfg.merge_from_dict({
        'train_cfg.max_epochs': EPOCHS,
        'train_cfg.val_begin': 100,
        'default_hooks.checkpoint.interval': 1,
        'default_hooks.checkpoint.max_keep_ckpts': EPOCHS,
        'randomness.seed': 0,
        'randomness.deterministic': True,
        'train_dataloader.dataset.indices': 1,
        **{
            f'{split}_dataloader.dataset.data_root': data_root
            for split in ('train', 'val', 'test')
        }
    })
    cfg.work_dir = str(work_dir)
    cfg.experiment_name = f'occcyl_resume_{uuid.uuid4().hex}'
    if resume_from is not None:
        cfg.resume, cfg.load_from = True, str(resume_from)
    return cfg


@pytest.mark.slow
def test_occcyl_resume_repeats_droppath(converted_tiny_world, tmp_path):
    """OccCylindrical (DropPath 0.1), one sample an epoch: resumed from
    epoch_1.pth, every tensor of epoch_2.pth equals the uninterrupted
    run's."""
    data_root = converted_tiny_world.rstrip('/') + '/'
    deterministic = torch.are_deterministic_algorithms_enabled()
    try:
        straight = tmp_path / 'straight'
        Runner.from_cfg(_occcyl_cfg(straight, data_root)).train()
        resumed = tmp_path / 'resumed'
        resumed.mkdir()
        shutil.copy(straight / 'epoch_1.pth', resumed / 'epoch_1.pth')
        Runner.from_cfg(
            _occcyl_cfg(resumed, data_root,
                        resumed / 'epoch_1.pth')).train()
    finally:
        torch.use_deterministic_algorithms(deterministic)
    final = f'epoch_{EPOCHS}.pth'
    expected = _state_dict(straight / final)
    got = _state_dict(resumed / final)
    assert list(got) == list(expected)
    differ = [name for name, tensor in expected.items()
              if not torch.equal(got[name], tensor)]
    assert differ == [], f'{len(differ)} of {len(expected)} differ'
