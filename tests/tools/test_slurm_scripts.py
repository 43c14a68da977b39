"""tools/slurm_train.sh and tools/slurm_test.sh hand srun mmdet3d's line.

No slurm here: a stand-in ``srun`` on PATH records its own options and then
runs the command it was given, with ``--help`` appended as the scripts'
extra ARGS, so the tool's argparse checks the line (``--launcher=slurm`` is
one of its choices, the positionals are in place) and exits 0 without
starting a job.
"""
import json
import os
import os.path as osp
import stat
import subprocess
import sys

import pytest

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))

FAKE_SRUN = '''#!{python}
import json, os, subprocess, sys
args = sys.argv[1:]
options = []
while args and args[0].startswith('-'):
    options.append(args.pop(0))
    if options[-1] == '-p':
        options.append(args.pop(0))
with open(os.environ['SRUN_RECORD'], 'w') as f:
    json.dump({{'options': options, 'command': args}}, f)
sys.exit(subprocess.call(args))
'''


def _run_script(tmp_path, script, *args, env=None):
    """Run tools/<script> with the stand-in srun; return (proc, record)."""
    bin_dir = tmp_path / 'bin'
    bin_dir.mkdir(exist_ok=True)
    srun = bin_dir / 'srun'
    srun.write_text(FAKE_SRUN.format(python=sys.executable))
    srun.chmod(srun.stat().st_mode | stat.S_IXUSR)
    record = tmp_path / 'srun.json'
    full_env = dict(os.environ,
                    PATH=f'{bin_dir}{os.pathsep}{os.environ["PATH"]}',
                    PYTHON=sys.executable,
                    SRUN_RECORD=str(record))
    full_env.update(env or {})
    proc = subprocess.run(['bash', osp.join(ROOT, 'tools', script), *args],
                          cwd=str(tmp_path), env=full_env,
                          capture_output=True, text=True, timeout=300)
    data = json.loads(record.read_text()) if record.exists() else None
    return proc, data


@pytest.mark.slow
@pytest.mark.parametrize('script,tool,fourth', [
    ('slurm_train.sh', 'train.py', 'work_dirs/run'),
    ('slurm_test.sh', 'test.py', 'epoch_24.pth'),
])
def test_srun_line_and_tool_arguments(tmp_path, script, tool, fourth):
    """GPUS=16 over GPUS_PER_NODE=8: 16 tasks, 8 per node, gpu:8 each
    node; the tool gets CONFIG, the fourth argument in its place and
    --launcher=slurm, then the extra ARGS (here --help: exit 0)."""
    config = 'configs/occ_cyl/occcyl_r50-swins_3xb1-24e_surroundocc-nus.py'
    proc, record = _run_script(
        tmp_path, script, 'gpu-part', 'occ', config, fourth, '--help',
        env={'GPUS': '16', 'GPUS_PER_NODE': '8', 'CPUS_PER_TASK': '6',
             'SRUN_ARGS': '--qos=high --time=10'})
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert 'usage' in proc.stdout
    assert record['options'] == [
        '-p', 'gpu-part', '--job-name=occ', '--gres=gpu:8', '--ntasks=16',
        '--ntasks-per-node=8', '--cpus-per-task=6', '--kill-on-bad-exit=1',
        '--qos=high', '--time=10'
    ]
    command = record['command']
    assert command[:3] == [sys.executable, '-u',
                           osp.join(ROOT, 'tools', tool)]
    if tool == 'train.py':
        assert command[3:] == [config, '--work-dir=work_dirs/run',
                               '--launcher=slurm', '--help']
    else:
        assert command[3:] == [config, 'epoch_24.pth', '--launcher=slurm',
                               '--help']


@pytest.mark.parametrize('script', ['slurm_train.sh', 'slurm_test.sh'])
def test_too_few_arguments_is_one_usage_line(tmp_path, script):
    """Three arguments of four: the usage line, exit 2, srun not run."""
    proc, record = _run_script(tmp_path, script, 'part', 'job', 'cfg.py')
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith('usage: ')
    assert len(proc.stderr.strip().splitlines()) == 1
    assert record is None
