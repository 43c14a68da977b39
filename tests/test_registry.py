"""The three plugin packages register their names once, in one process."""
import json
import subprocess
import sys

IMPORT_ALL = """
import json
import projects.occ_common, projects.occ_cyl, projects.sdg_occ
from mmdet3d.registry import DATASETS, HOOKS, METRICS, MODELS, TRANSFORMS
print(json.dumps({reg.name: {k: v.__module__.split('.')[1]
                             for k, v in reg.module_dict.items()
                             if v.__module__.startswith('projects.')}
                  for reg in (DATASETS, HOOKS, METRICS, MODELS, TRANSFORMS)}))
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
    owner = json.loads(proc.stdout.strip().splitlines()[-1])
    # Shared names live in occ_common, model names in their own package.
    assert owner['metric']['OccupancyMetric'] == 'occ_common'
    assert owner['dataset']['NuScenesOccDataset'] == 'occ_common'
    assert owner['model']['DepthNet'] == 'occ_common'
    assert owner['model']['SPVCNNEncoder'] == 'occ_common'
    assert owner['model']['OccCylindrical'] == 'occ_cyl'
    assert owner['model']['TPVPolarFusion'] == 'occ_cyl'
    assert owner['model']['SDGOcc'] == 'sdg_occ'
    assert owner['model']['NeighborhoodFusion'] == 'sdg_occ'
    assert owner['hook']['WeightsOnlyCheckpointHook'] == 'occ_common'
    assert owner['transform']['PackOccInputs'] == 'occ_common'


def test_no_plugin_module_forces_a_registration():
    """No source file under projects/ registers with ``force=True``."""
    import pathlib
    root = pathlib.Path(__file__).resolve().parents[1] / 'projects'
    offenders = [
        str(path) for path in root.rglob('*.py')
        if 'register_module(force=True' in path.read_text()
    ]
    assert offenders == []
