"""docs/customize_models.md's "Extending a module through the registry"
example works.

Its two code blocks are written out as a user would (``my_project/
my_fusion.py`` and ``my_config.py``, the ``<a config>`` placeholder filled
with the tiny OccCylindrical config) and the config's model is built in a
fresh process, so the example's registration does not leak into this one.
"""
import os
import os.path as osp
import re
import subprocess
import sys

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
TINY = 'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py'


def _extension_blocks():
    """The python blocks of the guide's extension section, in order."""
    with open(osp.join(ROOT, 'docs', 'customize_models.md')) as f:
        readme = f.read()
    section = readme.split('## Extending a module through the registry')[1]
    section = section.split('\n## ')[0]
    return re.findall(r'```python\n(.*?)```', section, flags=re.S)


def test_extension_example_builds(tmp_path):
    """The model built from my_config.py has a MyPolarFusion as its
    ``tpv_fusion``, a subclass of TPVPolarFusion."""
    module, config = _extension_blocks()
    assert module.startswith('# my_project/my_fusion.py')
    assert config.startswith('# my_config.py')
    package = tmp_path / 'my_project'
    package.mkdir()
    (package / '__init__.py').write_text('')
    (package / 'my_fusion.py').write_text(module)
    base = osp.join(ROOT, 'configs', 'occ_cyl', TINY)
    filled = config.replace("'configs/occ_cyl/<a config>.py'", repr(base))
    assert filled != config, 'the example changed its placeholder'
    (tmp_path / 'my_config.py').write_text(filled)
    script = (
        'from mmengine.config import Config\n'
        'from mmengine.registry import init_default_scope\n'
        'from mmdet3d.registry import MODELS\n'
        f'cfg = Config.fromfile({str(tmp_path / "my_config.py")!r})\n'
        "init_default_scope('mmdet3d')\n"
        'model = MODELS.build(cfg.model)\n'
        'from projects.occ_cyl import TPVPolarFusion\n'
        'fusion = model.tpv_fusion\n'
        'assert isinstance(fusion, TPVPolarFusion), type(fusion)\n'
        'print(type(fusion).__name__)\n')
    env = dict(os.environ,
               PYTHONPATH=f'{tmp_path}{osp.pathsep}{ROOT}')
    proc = subprocess.run([sys.executable, '-c', script], cwd=str(tmp_path),
                          env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.strip().splitlines()[-1] == 'MyPolarFusion'
