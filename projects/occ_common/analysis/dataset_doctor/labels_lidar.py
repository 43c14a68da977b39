"""Labels against LiDAR: do the key frame's points lie on the labels?

Occupancy labels are made from LiDAR (SurroundOcc meshes aggregated
sweeps, Occ3D voxelises them), so every point of the key frame lies on a
labelled surface: in an occupied voxel that borders free space (a
*surface* voxel), or in the free voxel just in front of one (a return at
the front of its voxel's face). The check measures the share of points
for which the voxel of the point, or of the point half a voxel further
along its ray, is a surface voxel (``hit``), and, where lidarseg exists,
whether a point's voxel holds its own class (``same_class``), overall and
per class (``<class>.hit``, ``<class>.same_class``).

Surface voxels and not occupied ones: labels with solid objects (the
synthetic world's, SurroundOcc's filled meshes) hold a point moved into
an object as well as one on it, so a grid shifted towards the sensor
would score as well as the true one; a point inside the solid is not on
its surface.

A frame mix-up or an off-by-one moves the labels against the points, and
the share is then higher *somewhere else*. The same share is measured with
the grid read another way: shifted by up to :data:`MAX_SHIFT` voxels per
axis, flipped along each axis, in the other frame (LiDAR instead of ego,
or the reverse) and with a voxel size 0.8 or 1.25 times the config's about
the grid's centre (Occ3D's 0.4 m against SurroundOcc's 0.5 m). A reading
that explains the points better than the config's by :data:`MARGIN` is a
failure naming it. Points near the ground fall in the one ground layer
however the grid is shifted along x or y, so the shares are also measured
on the points more than :data:`ELEVATED_M` above the sample's ground (its
points' 10th height percentile): cars, buildings and vegetation, which do
move with the grid.
"""
import itertools
from typing import Dict, List

import numpy as np

from ...datasets.nuscenes_classes import OCC_CLASS_NAMES
from .grid import LabelGrid
from .sample_data import SampleData
from .verdict import CheckResult

#: Shifts tried per axis, in voxels (every combination up to this).
MAX_SHIFT = 2
#: Voxel sizes tried, as factors of the config's (x and y).
VOXEL_FACTORS = (0.8, 1.25)
#: Height above the sample's ground (m) of the points that also count
#: alone: objects, which move with the grid where the ground does not.
ELEVATED_M = 1.0
#: A reading explains the points better when its share exceeds the
#: config's reading's by this much. On the synthetic world the config's
#: reading scores 0.98-1.00 and the best other one 0.03-0.04 below it
#: (a one-voxel shift along the street, which changes little).
MARGIN = 0.05
#: Below these shares of points on the labels' surfaces: failure, warning.
FAIL_HIT, WARN_HIT = 0.5, 0.8
#: Below this share of points whose voxel holds their lidarseg class: warn.
WARN_SAME_CLASS = 0.5
#: Fewer points than this in the grid: too few to judge.
MIN_POINTS = 50


def surface_voxels(occupied: np.ndarray) -> np.ndarray:
    """Occupied voxels with a free face neighbour (outside the grid is
    unknown, not free).

    Args:
        occupied (np.ndarray): bool. Shape (X, Y, Z).

    Returns:
        np.ndarray: bool. Shape (X, Y, Z).
    """
    padded = np.pad(occupied, 1, constant_values=True)
    free_face = np.zeros_like(occupied)
    centre = [slice(1, 1 + n) for n in occupied.shape]
    for axis in range(3):
        for start in (0, 2):
            window = list(centre)
            window[axis] = slice(start, start + occupied.shape[axis])
            free_face |= ~padded[tuple(window)]
    return occupied & free_face


class Reading:
    """Voxel indices of the points and of the points half a voxel further
    along their rays, under one reading of the grid.

    Args:
        name (str): How the grid is read.
        at (np.ndarray): Index of every point. Shape (P, 3).
        behind (np.ndarray): Index of every point moved half a voxel
            along its ray. Shape (P, 3).
        shape (Sequence[int]): The grid's shape.
    """

    def __init__(self, name: str, at: np.ndarray, behind: np.ndarray,
                 shape) -> None:
        self.name, self.at, self.behind = name, at, behind
        size = np.asarray(shape)
        self.inside = np.all((at >= 0) & (at < size), axis=1)
        self._behind_inside = np.all((behind >= 0) & (behind < size),
                                     axis=1)

    def on(self, voxels: np.ndarray) -> np.ndarray:
        """Which points have their voxel, or the one behind, in ``voxels``
        (bool (X, Y, Z)); a point outside the grid is not. Shape (P,)."""
        hit = np.zeros(len(self.at), bool)
        hit[self.inside] = voxels[tuple(self.at[self.inside].T)]
        behind = self.inside & self._behind_inside
        hit[behind] |= voxels[tuple(self.behind[behind].T)]
        return hit

    def shares(self, voxels: np.ndarray,
               subsets: Dict[str, np.ndarray]) -> Dict[str, float]:
        """Per subset of points (bool (P,)), the share :meth:`on`
        ``voxels`` (NaN for an empty subset). The subsets are the points
        in the grid as configured, so that a reading that moves points out
        of the grid counts them as misses."""
        hit = self.on(voxels)
        return {name: float(hit[subset].mean()) if subset.any()
                else float('nan') for name, subset in subsets.items()}


def _indices(points: np.ndarray, sensor: np.ndarray, low: np.ndarray,
             size: np.ndarray, step: float) -> tuple:
    """Voxel of every point, and of the point ``step`` metres further
    along its ray from ``sensor``."""
    ray = points - sensor
    ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-9)
    return (np.floor((points - low) / size).astype(np.int64),
            np.floor((points + step * ray - low) / size).astype(np.int64))


def configured_reading(xyz: np.ndarray, origin: np.ndarray,
                       grid: LabelGrid) -> Reading:
    """The config's own reading of the grid.

    Args:
        xyz (np.ndarray): Points in the labels' frame. Shape (P, 3).
        origin (np.ndarray): The sensor in the labels' frame. Shape (3,).
        grid (LabelGrid): The config's grid.

    Returns:
        Reading: Named ``'as configured'``.
    """
    return Reading('as configured',
                   *_indices(xyz, origin, grid.pc_range[:3],
                             grid.voxel_size,
                             0.5 * float(grid.voxel_size.min())), grid.shape)


def readings(xyz: np.ndarray, xyz_other_frame: np.ndarray,
             origin: np.ndarray, origin_other: np.ndarray,
             grid: LabelGrid) -> List[Reading]:
    """Every reading of the grid (see the module doc).

    Args:
        xyz (np.ndarray): Points in the labels' frame. Shape (P, 3).
        xyz_other_frame (np.ndarray): The same points in the other frame
            (LiDAR for Occ3D, ego for SurroundOcc). Shape (P, 3).
        origin (np.ndarray): The sensor in the labels' frame. Shape (3,).
        origin_other (np.ndarray): The sensor in the other frame.
        grid (LabelGrid): The config's grid.

    Returns:
        list[Reading]: The config's own reading (``'as configured'``)
        first.
    """
    shape = np.asarray(grid.shape)
    step = 0.5 * float(grid.voxel_size.min())
    low = grid.pc_range[:3]
    own = configured_reading(xyz, origin, grid)
    at, behind = own.at, own.behind
    out = [own]
    for shift in itertools.product(range(-MAX_SHIFT, MAX_SHIFT + 1),
                                   repeat=3):
        if any(shift):
            out.append(Reading(f'shifted by {shift} voxels', at + shift,
                               behind + shift, shape))
    for axis in range(3):
        flip = np.ones(3, np.int64)
        flip[axis] = -1
        offset = np.zeros(3, np.int64)
        offset[axis] = shape[axis] - 1
        out.append(Reading(f'flipped along {"xyz"[axis]}',
                           at * flip + offset, behind * flip + offset,
                           shape))
    other = 'LiDAR' if grid.frame == 'ego' else 'ego'
    out.append(Reading(f'in the {other} frame',
                       *_indices(xyz_other_frame, origin_other, low,
                                 grid.voxel_size, step), shape))
    centre = (grid.pc_range[:3] + grid.pc_range[3:]) / 2
    for factor in VOXEL_FACTORS:
        size = grid.voxel_size * np.array([factor, factor, 1.0])
        scaled_low = centre - size * shape / 2
        scaled_low[2] = low[2]
        out.append(Reading(f'with {factor:g} x the voxel size',
                           *_indices(xyz, origin, scaled_low, size, step),
                           shape))
    return out


def grid_points(sample: SampleData, grid: LabelGrid) -> tuple:
    """The sample's points and sensor in the labels' frame.

    Returns:
        tuple[np.ndarray, np.ndarray]: Points, Shape (P, 3), and the
        sensor's position, Shape (3,).
    """
    to_grid = grid.lidar2grid(sample.lidar2ego)
    pts = sample.points[:, :3].astype(np.float64)
    return pts @ to_grid[:3, :3].T + to_grid[:3, 3], to_grid[:3, 3]


def check_labels_vs_lidar(sample: SampleData,
                          grid: LabelGrid) -> CheckResult:
    """The ``labels_vs_lidar`` check of one sample (see the module doc).

    Args:
        sample (SampleData): With ``labels`` (else skipped).
        grid (LabelGrid): The config's grid.

    Returns:
        CheckResult: Numbers ``hit`` / ``hit_elevated`` (the config's
        reading), ``best_other.hit`` / ``best_other.hit_elevated`` and
        ``best_other.gain`` (the reading with the largest gain over it on
        either set of points, and that gain), ``points_in_grid``,
        ``same_class`` and per lidarseg class ``<class>.hit`` /
        ``<class>.same_class`` where lidarseg exists.
    """
    result = CheckResult('labels_vs_lidar')
    for sentence in sample.problems.get('labels_vs_lidar', []):
        result.fail(sentence)
    if sample.labels is None:
        if not result.findings:
            result.skipped = 'no occupancy labels'
        return result
    if tuple(sample.labels.shape) != tuple(grid.shape):
        result.fail(f'the labels are a {sample.labels.shape} grid, the '
                    f'config\'s is {grid.shape}')
        return result
    # The other frame: ego for LiDAR-frame labels, LiDAR for ego-frame ones.
    to_other = np.asarray(sample.lidar2ego) if grid.frame == 'lidar' \
        else np.eye(4)
    pts = sample.points[:, :3].astype(np.float64)
    xyz, origin = grid_points(sample, grid)
    all_readings = readings(xyz, pts @ to_other[:3, :3].T + to_other[:3, 3],
                            origin, to_other[:3, 3], grid)
    own_reading = all_readings[0]
    inside = own_reading.inside
    result.numbers['points_in_grid'] = float(inside.sum())
    if inside.sum() < MIN_POINTS:
        result.warn(f'only {int(inside.sum())} key-frame points lie in the '
                    'grid: too few to check the labels against')
        return result
    ground = np.percentile(xyz[inside, 2], 10)
    subsets = dict(hit=inside,
                   hit_elevated=inside & (xyz[:, 2] > ground + ELEVATED_M))
    surface = surface_voxels(grid.occupied(sample.labels))
    own = own_reading.shares(surface, subsets)
    result.numbers.update(own)
    scores = {r.name: r.shares(surface, subsets) for r in all_readings[1:]}
    # The largest gain on either set of points; among equal ones, the
    # larger on both (a shift that keeps every point beats one that drops
    # the lowest layer).
    rank = {name: (np.nanmax(gain), np.nansum(gain)) for name, gain in (
        (name, [score[k] - own[k] for k in own])
        for name, score in scores.items())}
    best = max(rank, key=rank.get)
    gains = {name: value[0] for name, value in rank.items()}
    result.numbers['best_other.gain'] = float(gains[best])
    result.numbers['best_other.hit'] = scores[best]['hit']
    result.numbers['best_other.hit_elevated'] = scores[best][
        'hit_elevated']
    if gains[best] > MARGIN:
        result.fail(
            f'the labels fit the LiDAR better {best}: '
            + ', '.join(f'{scores[best][k]:.2f} of the '
                        f'{"elevated " if "elevated" in k else ""}points '
                        f'on labelled surfaces against {own[k]:.2f} as '
                        'configured' for k in own
                        if scores[best][k] - own[k] > MARGIN)
            + ' (a frame mix-up, a grid origin or voxel size other than '
            "the labels', or a flipped axis)")
    result.judge(own['hit'], '{value:.2f} of the key frame\'s LiDAR points '
                 'lie on labelled surfaces', lambda v: v < FAIL_HIT,
                 lambda v: v < WARN_HIT)
    if sample.lidarseg is not None:
        _per_class(result, sample.lidarseg, sample.labels, own_reading,
                   surface)
    return result


def _per_class(result: CheckResult, lidarseg: np.ndarray,
               labels: np.ndarray, reading: Reading,
               surface: np.ndarray) -> None:
    """``same_class`` overall and ``hit`` / ``same_class`` per lidarseg
    class (1..16, the classes both label formats share)."""
    valid = reading.inside & (lidarseg >= 1) & (lidarseg <= len(
        OCC_CLASS_NAMES))
    if not valid.any():
        return
    seg = lidarseg[valid]
    same = np.zeros(len(seg), bool)
    for label in np.unique(seg):
        of_label = seg == label
        same[of_label] = reading.on(labels == label)[valid][of_label]
    hit = reading.on(surface)[valid]
    result.numbers['same_class'] = float(same.mean())
    for label, name in enumerate(OCC_CLASS_NAMES, start=1):
        of_class = seg == label
        if of_class.any():
            result.numbers[f'{name}.hit'] = float(hit[of_class].mean())
            result.numbers[f'{name}.same_class'] = float(
                same[of_class].mean())
    result.judge(float(same.mean()), '{value:.2f} of the labelled points '
                 'lie in a voxel of their own lidarseg class (class '
                 'numbers shifted, or another class table?)',
                 lambda v: False, lambda v: v < WARN_SAME_CLASS)
