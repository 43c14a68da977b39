"""Two-rank training and testing under torchrun (gloo on CPU).

tools/dist_train.sh trains the toy config with 2 ranks; tools/dist_test.sh
evaluates the checkpoint with 2 ranks, each seeing half of the 4 val
samples; the metrics gathered across ranks (the voxel metric's confusion
matrix and RayIoU's ray counts) must equal single-process tools/test.py
on the same checkpoint, to the last digit of the json log.
"""
import os
import os.path as osp
import subprocess
import sys

import pytest

from projects.occ_common.analysis.ddp_check import free_port
from projects.occ_common.testing.tool_logs import last_test_metrics

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')
#: The same model, tested with RayIoU beside the voxel metric.
RAY_CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ_rayiou.py')


def _run(cmd, env=None):
    """Run a tool with the test's interpreter; return the process."""
    # CUDA hidden: the ranks run on the CPU under gloo even where a GPU is.
    # With CUDA visible, mmengine's init_dist calls torch.cuda.set_device(
    # LOCAL_RANK), and rank 1 has no cuda:1 on a one-GPU machine (the test
    # failed on a lent H200).
    full_env = dict(os.environ, PYTHON=sys.executable, OMP_NUM_THREADS='1',
                    CUDA_VISIBLE_DEVICES='')
    full_env.update(env or {})
    return subprocess.run(cmd, cwd=ROOT, env=full_env, capture_output=True,
                          text=True, timeout=400)


def _metrics(work_dir):
    """The occ/* values of the newest test run's json log."""
    return {
        k: v
        for k, v in last_test_metrics(work_dir).items()
        if k.startswith('occ/')
    }


@pytest.mark.slow
def test_two_rank_train_then_gathered_metric_equals_single_process(
        tmp_path):
    """1 epoch: 8 samples / (2 ranks x batch 2) = 2 iterations per rank.

    Testing: 4 samples / (2 ranks x batch 2) = 1 iteration per rank, so
    the 2-rank log shows [1/1] where the single process shows [2/2], and
    OccupancyMetric sums the confusion matrices of both ranks and
    OccRayIoUMetric pools their ray counts before dividing.
    """
    work_dir = str(tmp_path / 'train')
    proc = _run([
        'bash', osp.join(ROOT, 'tools', 'dist_train.sh'), CONFIG, '2',
        '--work-dir', work_dir, '--cfg-options', 'train_cfg.max_epochs=1'
    ], env=dict(PORT=str(free_port())))
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-4000:]
    output = proc.stdout + proc.stderr
    assert 'Epoch(train) [1][2/2]' in output
    checkpoint = osp.join(work_dir, 'epoch_1.pth')
    assert osp.isfile(checkpoint)

    dist_dir = str(tmp_path / 'dist_test')
    proc = _run([
        'bash', osp.join(ROOT, 'tools', 'dist_test.sh'), RAY_CONFIG,
        checkpoint, '2', '--work-dir', dist_dir
    ], env=dict(PORT=str(free_port())))
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-4000:]
    assert 'Epoch(test) [1/1]' in proc.stdout + proc.stderr

    single_dir = str(tmp_path / 'single_test')
    proc = _run([
        sys.executable, osp.join(ROOT, 'tools', 'test.py'), RAY_CONFIG,
        checkpoint, '--work-dir', single_dir
    ])
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert 'Epoch(test) [2/2]' in proc.stdout + proc.stderr

    gathered, single = _metrics(dist_dir), _metrics(single_dir)
    assert {'occ/IoU', 'occ/mIoU', 'occ/car', 'occ/road', 'occ/RayIoU',
            'occ/RayIoU@1', 'occ/RayIoU/car'} <= set(single)
    assert gathered == single
