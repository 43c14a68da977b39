"""tools/analysis_tools/gpu_check.sh without a GPU: a clear refusal, and
the configs and test marker it names exist."""
import os
import os.path as osp
import re
import subprocess
import sys

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SCRIPT = osp.join(ROOT, 'tools', 'analysis_tools', 'gpu_check.sh')


def test_refuses_without_cuda(tmp_path):
    """Exit 2 and the reason on stderr, nothing run."""
    env = dict(os.environ, PYTHON=sys.executable, CUDA_VISIBLE_DEVICES='')
    proc = subprocess.run(['bash', SCRIPT, str(tmp_path / 'out')], cwd=ROOT,
                          env=env, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2
    assert 'gpu_check: no CUDA device visible' in proc.stderr
    assert not (tmp_path / 'out' / 'summary.json').exists()


def test_named_configs_and_marker_exist():
    text = open(SCRIPT).read()
    configs = re.findall(r'configs/\S+\.py', text)
    assert len(configs) == 3
    assert all(osp.isfile(osp.join(ROOT, c)) for c in configs)
    assert '-m cuda' in text
    setup = open(osp.join(ROOT, 'setup.cfg')).read()
    assert re.search(r'^\s+cuda: ', setup, re.M)
    subprocess.run(['bash', '-n', SCRIPT], check=True)
