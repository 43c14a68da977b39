"""The three plugin packages register their names once, in one process."""
import subprocess
import sys

IMPORT_ALL = """
import projects.occ_common, projects.occ_cyl, projects.sdg_occ
from mmdet3d.registry import DATASETS, METRICS, MODELS, TRANSFORMS
names = {reg.name: sorted(k for k, v in reg.module_dict.items()
                          if v.__module__.startswith('projects.'))
         for reg in (DATASETS, METRICS, MODELS, TRANSFORMS)}
print(names)
"""


def test_all_packages_import_together_without_collision():
    """Importing every package in one fresh process raises nothing.

    mmengine's ``Registry.register_module`` raises ``KeyError`` on a second
    registration of a name without ``force=True``, so a clean import of all
    three packages proves that no name is registered twice. The import runs
    in a subprocess so that earlier tests cannot have registered anything.
    """
    proc = subprocess.run([sys.executable, '-c', IMPORT_ALL],
                          capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr
    assert 'already registered' not in proc.stderr


def test_no_plugin_module_forces_a_registration():
    """No source file under projects/ registers with ``force=True``."""
    import pathlib
    root = pathlib.Path(__file__).resolve().parents[1] / 'projects'
    offenders = [
        str(path) for path in root.rglob('*.py')
        if 'register_module(force=True' in path.read_text()
    ]
    assert offenders == []
