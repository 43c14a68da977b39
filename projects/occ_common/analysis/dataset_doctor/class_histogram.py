"""Class histogram: the labels' class shares against a reference.

Per sample, the voxels of every label (``voxels.<class>``) and the share
of the grid that is empty (``empty_share``): labels whose empty value is
not the format's (a label set read with another's numbers) are mostly
"occupied", a failure. Over the split, the shares of the 16 nuScenes
classes among the occupied voxels are compared with the reference of the
label set (:data:`REFERENCES`) by their total variation distance (half
the sum of absolute differences: 0 alike, 1 disjoint); a distance above
:data:`WARN_DISTANCE` is a warning, as a dataset of other streets can
differ that much on purpose.

The references:

* ``occ3d``: the voxel counts of Occ3D-nuScenes' labels that FlashOCC
  weights its loss with (github.com/Yzichen/FlashOCC, file
  ``projects/mmdet3d_plugin/models/dense_heads/bev_occ_head.py``,
  ``nusc_class_frequencies``, read 2026-11): 18 counts, ``others`` to
  ``free``; their ``free`` share, 77.5 %, is below the whole grid's, so
  they are not all the grid's voxels, and only the occupied classes'
  shares are compared.
* ``surroundocc``: no class counts of SurroundOcc's labels are published
  (its paper and repository give none; looked up 2026-11), so the 16
  classes' shares among the occupied voxels are Occ3D's above: the same
  nuScenes scenes and lidarseg classes, voxelised at 0.5 m over 100 m
  instead of 0.4 m over 80 m.
* a synthetic world (its info file's metainfo says ``synthetic``): the
  counts of the generator's default world (``create_synthetic_nuscenes.py
  data/nuscenes_synthetic``: 2 scenes of 4 key frames, seed 0), measured
  on all 8 key frames with the generator of commit 01b0e80 (its labels
  do not depend on the image size).
"""
from typing import Dict, Sequence

import numpy as np

from ...datasets.nuscenes_classes import OCC_CLASS_NAMES
from .grid import LabelGrid
from .sample_data import SampleData
from .verdict import CheckResult

#: Occ3D-nuScenes voxel counts, ``others``, the 16 classes, ``free``
#: (FlashOCC's ``nusc_class_frequencies``; see the module doc).
OCC3D_NUSCENES_COUNTS = (944004, 1897170, 152386, 2391677, 16957802, 724139,
                         189027, 2074468, 413451, 2384460, 5916653,
                         175883646, 4275424, 51393615, 61411620, 105975596,
                         116424404, 1892500630)
#: The 16 classes' voxels (``barrier`` .. ``vegetation``) of the synthetic
#: default world's SurroundOcc and Occ3D labels (see the module doc).
SYNTHETIC_COUNTS = dict(
    surroundocc=(673, 753, 9215, 22287, 3752, 576, 3784, 118, 8712, 5281,
                 77627, 5175, 18208, 180285, 273550, 28550),
    occ3d=(915, 808, 16497, 29135, 4203, 908, 5505, 213, 14540, 7163, 95647,
           7785, 22308, 152633, 402346, 37979))
#: A total variation distance of the class shares above this: warn.
WARN_DISTANCE = 0.35
#: Less of the grid than this empty: fail; more than this: warn.
FAIL_EMPTY, WARN_EMPTY = 0.5, 0.9999


def reference_shares(occ_format: str, synthetic: bool) -> tuple:
    """The reference shares of the 16 classes among occupied voxels.

    Args:
        occ_format (str): ``'surroundocc'`` or ``'occ3d'``.
        synthetic (bool): The data is the synthetic world.

    Returns:
        tuple[np.ndarray, str]: Shares in :data:`OCC_CLASS_NAMES` order,
        Shape (16,), and where they come from.
    """
    if synthetic:
        counts = np.asarray(SYNTHETIC_COUNTS[occ_format], np.float64)
        source = 'the synthetic default world\'s labels'
    else:
        counts = np.asarray(OCC3D_NUSCENES_COUNTS[1:17], np.float64)
        source = "Occ3D-nuScenes' labels (FlashOCC's class counts)"
    return counts / counts.sum(), source


def check_histogram(sample: SampleData, grid: LabelGrid) -> CheckResult:
    """The per-sample ``class_histogram`` check.

    Args:
        sample (SampleData): The sample.
        grid (LabelGrid): The config's grid.

    Returns:
        CheckResult: ``voxels.<class>`` per class name of the grid and
        ``empty_share``.
    """
    result = CheckResult('class_histogram')
    if sample.labels is None:
        result.skipped = 'no occupancy labels'
        return result
    labels = sample.labels.ravel()
    counts = np.bincount(labels[labels != grid.ignore_index],
                         minlength=len(grid.class_names))
    for name, count in zip(grid.class_names, counts):
        result.numbers[f'voxels.{name}'] = float(count)
    extra = counts[len(grid.class_names):]
    if extra.any():
        result.fail(f'{int(extra.sum())} voxels hold labels beyond the '
                    f'{len(grid.class_names)} classes of the config')
    empty = float(counts[grid.empty_label] / max(1, labels.size))
    result.numbers['empty_share'] = empty
    result.judge(empty, f'{{value:.3f}} of the grid is labelled '
                 f'{grid.class_names[grid.empty_label]!r} (the empty value '
                 'of another label set?)', lambda v: v < FAIL_EMPTY,
                 lambda v: v > WARN_EMPTY)
    return result


def class_shares(counts: Dict[str, float]) -> np.ndarray:
    """The 16 classes' shares among their voxels, Shape (16,)."""
    values = np.array([counts.get(name, 0.0) for name in OCC_CLASS_NAMES])
    return values / values.sum() if values.sum() else values


def split_histogram(results: Sequence[CheckResult], grid: LabelGrid,
                    synthetic: bool) -> CheckResult:
    """The split's ``class_histogram`` against the reference.

    Args:
        results (Sequence[CheckResult]): The per-sample results.
        grid (LabelGrid): The config's grid.
        synthetic (bool): The data is the synthetic world.

    Returns:
        CheckResult: ``share.<class>`` and ``reference.<class>`` of the 16
        classes, ``distance`` (total variation) and ``voxels``.
    """
    result = CheckResult('class_histogram')
    totals: Dict[str, float] = {}
    for sample_result in results:
        for key, value in sample_result.numbers.items():
            if key.startswith('voxels.'):
                name = key[len('voxels.'):]
                totals[name] = totals.get(name, 0.0) + value
    if not totals:
        result.skipped = 'no occupancy labels'
        return result
    shares = class_shares(totals)
    reference, source = reference_shares(grid.occ_format, synthetic)
    for name, share, ref in zip(OCC_CLASS_NAMES, shares, reference):
        result.numbers[f'share.{name}'] = float(share)
        result.numbers[f'reference.{name}'] = float(ref)
    distance = float(np.abs(shares - reference).sum() / 2)
    result.numbers['distance'] = distance
    result.numbers['voxels'] = float(sum(totals.values()))
    result.judge(distance, 'the class shares differ from '
                 f'{source} by {{value:.2f}} (total variation): another '
                 'class table, or other streets?', lambda v: False,
                 lambda v: v > WARN_DISTANCE)
    return result
