"""Read what tools/test.py logged, for end-to-end tests of the tools."""
import glob
import json
import math
import os.path as osp
from typing import Dict, Sequence


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
    logs = sorted(glob.glob(osp.join(work_dir, '*', '*.json')))
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
