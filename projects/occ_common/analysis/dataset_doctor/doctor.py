"""The dataset doctor: every check on the samples of a config's split.

:func:`run_doctor` builds the split's dataset from the config (through
:func:`~...apis.split_dataset.build_split_dataset`, as the other analysis
tools do), reads each chosen sample's files as they are
(:mod:`.sample_data`) and runs the checks of the families below on it;
over the split it adds the config's grid against its labels
(:func:`.grid.grid_config_check`) and the class histogram against its
reference. ``tools/analysis_tools/check_dataset.py`` is its command line;
:mod:`.report` writes what it found.

Families (:data:`CHECKS`): ``calibration``, ``labels_vs_lidar``
(with ``label_grid``), ``masks``, ``sequence``, ``class_histogram``.
"""
import os.path as osp
import time
from dataclasses import dataclass, field
from typing import Dict, List, Optional

import numpy as np

from ...apis.split_dataset import build_split_dataset
from ...fileio.safe_names import safe_file_name
from .calibration import check_calibration
from .class_histogram import check_histogram, split_histogram
from .grid import LabelGrid, grid_config_check, grid_from_config
from .labels_lidar import check_labels_vs_lidar
from .masks import check_masks
from .pictures import bev_picture, camera_picture
from .sample_data import load_sample
from .sequence import check_sequence
from .verdict import CheckResult, CheckSummary, summarise, worst

#: The check families, in the report's order.
CHECKS = ('calibration', 'labels_vs_lidar', 'label_grid', 'masks',
          'sequence', 'class_histogram')


@dataclass
class DoctorReport:
    """What the doctor found.

    Args:
        config (str): The config file.
        split (str): ``'val'`` or ``'train'``.
        ann_file (str): The split's info file.
        data_root (str): Its data root.
        num_samples (int): Samples in the split.
        tokens (list[str]): The checked samples, in order.
        results (list[dict[str, CheckResult]]): Per checked sample, its
            result of every family.
        summaries (dict[str, CheckSummary]): Per family, over the split.
        pictures (list[str]): Picture files written (relative to the
            output folder).
        seconds_per_sample (float): Mean time of one sample's checks
            (pictures excluded).
    """
    config: str
    split: str
    ann_file: str
    data_root: str
    num_samples: int
    tokens: List[str] = field(default_factory=list)
    results: List[Dict[str, CheckResult]] = field(default_factory=list)
    summaries: Dict[str, CheckSummary] = field(default_factory=dict)
    pictures: List[str] = field(default_factory=list)
    seconds_per_sample: float = float('nan')

    @property
    def verdict(self) -> str:
        """str: The worst verdict of all families."""
        return worst(s.verdict for s in self.summaries.values())


def sample_indices(length: int, count: Optional[int]) -> List[int]:
    """``count`` sample indices spread evenly over ``length`` samples, the
    first and last included (all of them for ``count`` None or larger).

    Args:
        length (int): Samples in the split.
        count (int, optional): How many to check.

    Returns:
        list[int]: Sorted, unique indices.
    """
    if count is None or count >= length:
        return list(range(length))
    if count < 1:
        raise ValueError(f'--samples must be >= 1, got {count}')
    return sorted({int(round(i)) for i in np.linspace(0, length - 1,
                                                      count)})


def check_sample(sample, grid: LabelGrid, dataset) -> Dict[str, CheckResult]:
    """Every per-sample check of one sample."""
    return dict(calibration=check_calibration(sample),
                labels_vs_lidar=check_labels_vs_lidar(sample, grid),
                masks=check_masks(sample, grid),
                sequence=check_sequence(sample, dataset),
                class_histogram=check_histogram(sample, grid))


def run_doctor(cfg,
               split: str = 'val',
               num_samples: Optional[int] = None,
               out_dir: Optional[str] = None,
               pictures: int = 2,
               data_root: Optional[str] = None,
               with_images: bool = True) -> DoctorReport:
    """Check the samples of a config's split.

    Args:
        cfg (Config): The merged config.
        split (str): ``'val'`` (the test dataloader's) or ``'train'``.
            Defaults to 'val'.
        num_samples (int, optional): Samples to check, spread over the
            split. Defaults to None (all).
        out_dir (str, optional): Where the pictures go (``pictures/``).
            Defaults to None (no pictures).
        pictures (int): Samples drawn (the first checked ones).
            Defaults to 2.
        data_root (str, optional): Replaces the dataset's ``data_root``.
        with_images (bool): Read the camera images (the image checks
            need them). Defaults to True.

    Returns:
        DoctorReport: The results.
    """
    from ...visualization import save_png
    dataset = build_split_dataset(cfg, split, data_root)
    grid = grid_from_config(cfg, dataset)
    report = DoctorReport(config=cfg.filename or '<config>', split=split,
                          ann_file=dataset.ann_file,
                          data_root=dataset.data_root,
                          num_samples=len(dataset))
    seconds = []
    for rank, index in enumerate(sample_indices(len(dataset), num_samples)):
        start = time.perf_counter()
        sample = load_sample(dataset, index, with_images,
                             cfg.get('ego_box'))
        report.results.append(check_sample(sample, grid, dataset))
        seconds.append(time.perf_counter() - start)
        report.tokens.append(sample.token)
        if out_dir is not None and rank < pictures:
            for name, picture in (('cameras', camera_picture(sample, grid)),
                                  ('bev', bev_picture(sample, grid))):
                if picture is not None:
                    token = safe_file_name(sample.token, 'sample token')
                    rel = osp.join('pictures', f'{token}_{name}.png')
                    save_png(picture, osp.join(out_dir, rel))
                    report.pictures.append(rel)
    report.seconds_per_sample = float(np.mean(seconds)) if seconds \
        else float('nan')
    synthetic = bool(dataset.metainfo.get('synthetic', False))
    split_results = dict(
        label_grid=grid_config_check(grid),
        class_histogram=split_histogram(
            [r['class_histogram'] for r in report.results], grid,
            synthetic))
    for check in CHECKS:
        per_sample = [r[check] for r in report.results if check in r]
        tokens = [t for t, r in zip(report.tokens, report.results)
                  if check in r]
        report.summaries[check] = summarise(check, per_sample, tokens,
                                            split_results.get(check))
    return report
