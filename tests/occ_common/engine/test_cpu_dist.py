"""The distributed backend follows the device: nccl on CUDA, gloo on CPU.

Every config names nccl (mmdet3d's default, the backend for CUDA
tensors), which the Runner passes to ``init_process_group`` unchanged on a
GPU machine; the configs used to name gloo, so GPU runs all-reduced their
gradients through gloo. Without CUDA the tools start the ranks with
:func:`cpu_backend`, gloo in nccl's place (nccl cannot run on the CPU; the
two-rank tests in tests/tools/test_dist_train.py run that path).
"""
import glob
import os.path as osp

import pytest
from mmengine.config import Config

from projects.occ_common.engine.cpu_dist import cpu_backend

ROOT = osp.dirname(
    osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__)))))
PAPER_CONFIGS = sorted(
    glob.glob(osp.join(ROOT, 'configs', '*', '*_[34]xb[12]-24e_*.py')))


def test_paper_configs_are_found():
    """Four OccCylindrical and eight SDG-OCC paper configs (SDG-KL over two
    frames the eighth) at the top level of configs/occ_cyl/ and
    configs/sdg_occ/, three of them the Occ3D configs trained without the
    camera mask (``*-nomask.py``)."""
    names = [osp.basename(p) for p in PAPER_CONFIGS]
    assert sum(n.startswith('occcyl') for n in names) == 4
    assert sum(n.startswith('sdgocc') for n in names) == 8
    assert sum(n.endswith('-nomask.py') for n in names) == 3


@pytest.mark.parametrize('path', PAPER_CONFIGS, ids=osp.basename)
def test_paper_configs_use_nccl(path):
    assert Config.fromfile(path).env_cfg.dist_cfg.backend == 'nccl'


@pytest.mark.parametrize('dist_cfg,expected', [
    (dict(backend='nccl'), 'gloo'),
    (dict(backend='gloo'), 'gloo'),
    (dict(backend='mpi'), 'mpi'),
    (dict(), 'gloo'),
])
def test_cpu_backend(dist_cfg, expected):
    """nccl and a missing backend become gloo; a CPU backend stays."""
    assert cpu_backend(dist_cfg) == expected
