"""Read what tools/test.py logged, for end-to-end tests of the tools."""
import contextlib
import glob
import json
import math
import os.path as osp
import subprocess
import sys
from typing import Dict, List, Sequence, Tuple

# load_tool is re-exported: the tests load tool scripts through this module.
from projects.occ_common.analysis.tool_runs import REPO_ROOT, load_tool


def last_test_metrics(work_dir: str, prefix: str = 'occ/') -> Dict:
    """The metrics record of the newest run's json log under ``work_dir``.

    mmengine's LoggerHook writes ``{work_dir}/{timestamp}/{timestamp}.json``
    with one record per logged step; the test record holds the metrics.

    Args:
        work_dir (str): ``--work-dir`` of a tools/test.py run.
        prefix (str): Prefix of the metric keys. Defaults to 'occ/'.

    Returns:
        dict: The last record holding ``{prefix}mIoU``.
    """
    logs = sorted(glob.glob(osp.join(glob.escape(work_dir), '*', '*.json')))
    if not logs:
        raise FileNotFoundError(f'no json log under {work_dir}')
    with open(logs[-1]) as f:
        records = [json.loads(line) for line in f if line.strip()]
    found = [r for r in records if f'{prefix}mIoU' in r]
    if not found:
        raise KeyError(f'{logs[-1]} holds no {prefix}mIoU record')
    return found[-1]


def mean_of_class_ious(metrics: Dict,
                       class_names: Sequence[str],
                       prefix: str = 'occ/') -> float:
    """Mean of the logged per-class IoUs, skipping NaN (absent) classes.

    This is how OccupancyMetric defines mIoU in both conventions, so a
    logged ``mIoU`` must equal it (up to the log's 4-decimal rounding).
    """
    values = [metrics[f'{prefix}{name}'] for name in class_names]
    finite = [v for v in values if not math.isnan(v)]
    return sum(finite) / len(finite)


def train_losses(work_dir: str) -> List[float]:
    """The total ``loss`` of every logged training iteration, in order.

    Read from the newest run's ``vis_data/*.json`` scalars of ``work_dir``.
    """
    logs = sorted(
        glob.glob(osp.join(glob.escape(work_dir), '*', 'vis_data', '*.json')))
    if not logs:
        raise FileNotFoundError(f'no scalars json under {work_dir}')
    with open(logs[-1]) as f:
        records = [json.loads(line) for line in f if line.strip()]
    return [r['loss'] for r in records if 'loss' in r]


def run_tool(script: str,
             *args: str,
             timeout: float = 900,
             cwd: str = REPO_ROOT) -> subprocess.CompletedProcess:
    """Run a tool script (a path relative to the repository root) with this
    interpreter, from the repo root by default."""
    return subprocess.run([sys.executable,
                           osp.join(REPO_ROOT, script), *args],
                          cwd=cwd,
                          capture_output=True,
                          text=True,
                          timeout=timeout)


def run_create_data(*argv: str):
    """``tools/create_data.py nuscenes ARGV`` run in this process.

    Returns:
        dict[str, str]: Split name -> written info file.
    """
    return load_tool('tools/create_data.py').main(['nuscenes', *argv])


def make_converted_world(root: str, scenes: int, samples: int, sweeps: int,
                         image_size: Tuple[int, int]) -> str:
    """Generate a synthetic world with the CLI and convert it.

    Goes through ``tools/dataset_converters/create_synthetic_nuscenes.py`` and
    ``tools/create_data.py`` exactly as a user would.

    Args:
        root (str): Folder to write the world to.
        scenes (int): Number of scenes (the last is the val split).
        samples (int): Key frames per scene.
        sweeps (int): LiDAR sweeps per key-frame interval.
        image_size (tuple[int]): ``(W, H)`` of the camera images.

    Returns:
        str: ``root`` with a trailing slash, as configs expect a data_root.
    """
    proc = run_tool('tools/dataset_converters/create_synthetic_nuscenes.py',
                    root, '--scenes', str(scenes), '--samples', str(samples),
                    '--sweeps', str(sweeps), '--image-size',
                    str(image_size[0]), str(image_size[1]))
    if proc.returncode != 0:
        raise RuntimeError(f'world generation failed: {proc.stderr[-3000:]}')
    proc = run_tool('tools/create_data.py', 'nuscenes', '--root-path', root,
                    '--version', 'v1.0-mini')
    if proc.returncode != 0:
        raise RuntimeError(f'conversion failed: {proc.stderr[-3000:]}')
    return root.rstrip('/') + '/'


def export_onnx_report(config: str, out: str,
                       verify: Sequence[str]) -> Dict:
    """``tools/deployment/export_onnx.py CONFIG none --out OUT --verify
    ...`` in this process, its printing silenced.

    Args:
        config (str): Config file.
        out (str): The ``.onnx`` file to write.
        verify (Sequence[str]): ``--verify`` samples.

    Returns:
        dict: The tool's report (what it writes to ``FILE.json``).
    """
    import contextlib
    import io
    with contextlib.redirect_stdout(io.StringIO()):
        return load_tool('tools/deployment/export_onnx.py').main(
            [config, 'none', '--out', out, '--verify', *verify])


@contextlib.contextmanager
def quiet_logger():
    """mmengine's current logger at WARNING within the block: a paper
    model's ``init_weights`` logs every parameter's initialisation at INFO
    (1.5 k lines)."""
    import logging

    from mmengine.logging import MMLogger
    logger = MMLogger.get_current_instance()
    level = logger.level
    logger.setLevel(logging.WARNING)
    try:
        yield
    finally:
        logger.setLevel(level)


def occcyl_graph_parity(report: Dict, sample: str) -> Tuple[Dict, Dict]:
    """The verification of an OccCylindrical export on ``sample``: the
    prediction graph's (logits against the model's own forward) and the
    camera graph's (depth and context against its module), from
    :func:`export_onnx_report`'s report."""
    graphs = report['graphs']
    return (graphs['prediction']['verify'][sample],
            graphs['camera']['verify'][sample])
