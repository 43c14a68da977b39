"""tools/train.py -> checkpoint -> --resume -> tools/test.py under torch 2.13.

Runs the toy config (tests/data/configs/toy_occ.py) in subprocesses, as a
user would, with weights-only checkpoint loading left on.
"""
import os.path as osp
import subprocess
import sys

import numpy as np
import pytest
import torch

from projects.occ_common.testing.tool_logs import last_test_metrics, load_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


def run_tool(script, *args):
    """Run a tool (a path relative to the repo root); return the
    completed process."""
    proc = subprocess.run(
        [sys.executable, osp.join(ROOT, script), *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300)
    return proc


def hand_computed_miou(checkpoint):
    """mIoU over classes 1..2 of the toy val split, recomputed in numpy.

    IoU_c = TP_c / (TP_c + FP_c + FN_c) with counts summed over all four
    val samples (the SurroundOcc convention), reported in percent.
    """
    from projects.occ_common.fileio import load_checkpoint_file
    from projects.occ_common.testing.toy_model import (ToyOccupancyDataset,
                                                       ToyOccupancyModel)
    ckpt = load_checkpoint_file(checkpoint, map_location='cpu')
    model = ToyOccupancyModel(in_channels=3, num_classes=3)
    model.load_state_dict(ckpt['state_dict'])
    dataset = ToyOccupancyDataset(num_samples=4, num_classes=3, seed=100)
    tp = np.zeros(3)
    fp = np.zeros(3)
    fn = np.zeros(3)
    for idx in range(len(dataset)):
        info = dataset.get_data_info(idx)
        with torch.no_grad():
            pred = model(info['inputs'][None]).argmax(1)[0].numpy()
        gt = info['gt_occ'].numpy()
        for c in range(3):
            tp[c] += np.sum((pred == c) & (gt == c))
            fp[c] += np.sum((pred == c) & (gt != c))
            fn[c] += np.sum((pred != c) & (gt == c))
    iou = tp / (tp + fp + fn)
    return 100 * iou[1:].mean()


@pytest.mark.slow
def test_train_resume_and_test(tmp_path):
    """Train 2 epochs, resume to 3, evaluate the epoch-3 checkpoint."""
    work_dir = str(tmp_path / 'work')
    proc = run_tool('tools/train.py', CONFIG, '--work-dir', work_dir)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert osp.isfile(osp.join(work_dir, 'epoch_2.pth'))
    with open(osp.join(work_dir, 'last_checkpoint')) as f:
        assert f.read().strip().endswith('epoch_2.pth')

    proc = run_tool('tools/train.py', CONFIG, '--work-dir', work_dir,
                    '--resume', '--cfg-options', 'train_cfg.max_epochs=3')
    assert proc.returncode == 0, proc.stderr[-3000:]
    output = proc.stdout + proc.stderr
    assert 'resumed epoch: 2, iter: 8' in output
    ckpt3 = osp.join(work_dir, 'epoch_3.pth')
    from projects.occ_common.fileio import load_checkpoint_file
    meta = load_checkpoint_file(ckpt3)['meta']
    # 8 samples / batch 2 = 4 iterations per epoch: 3 epochs = 12 iters.
    assert (meta['epoch'], meta['iter']) == (3, 12)

    test_dir = str(tmp_path / 'test')
    proc = run_tool('tools/test.py', CONFIG, ckpt3, '--work-dir', test_dir)
    assert proc.returncode == 0, proc.stderr[-3000:]
    miou = last_test_metrics(test_dir)['occ/mIoU']
    assert miou == pytest.approx(hand_computed_miou(ckpt3), abs=0.01)
    # A trained 1x1x1 conv separates one-hot + 0.5 noise well: far above
    # the ~20 % of a random 3-way guess.
    assert miou > 60


def test_resume_from_explicit_checkpoint_path(tmp_path):
    """``--resume PATH`` sets ``resume=True`` and ``load_from=PATH``."""
    train = load_tool('tools/train.py')
    args = train.parse_args([CONFIG, '--resume', 'some/ckpt.pth'])
    cfg = train.build_cfg(args)
    assert (cfg.resume, cfg.load_from) == (True, 'some/ckpt.pth')
    args = train.parse_args([CONFIG, '--resume'])
    cfg = train.build_cfg(args)
    assert (cfg.resume, cfg.load_from) == (True, None)
    assert cfg.work_dir == osp.join('./work_dirs', 'toy_occ')
