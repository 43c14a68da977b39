"""Do the LiDAR and the images show the same scene at the same pixels?

Two measures of a sample's images against its LiDAR points, both made to
tell a right calibration from a wrong one without a target:

* :func:`edge_alignment`, per camera: the LiDAR's *reflectivity edges*
  (lane paint, kerbs, signs: a point whose return is several times
  brighter or darker than its neighbour's on the same scan line) should
  land on the image's intensity edges. The score is the image's mean edge
  strength at those points over its mean at the same points moved
  sideways by a few percent of the width (what chance gives): about 1
  means no alignment. It is Levinson & Thrun's target-less criterion (RSS
  2013) reduced to one number per camera, with reflectivity edges in place
  of range edges: range edges sit where the LiDAR and the camera, a metre
  apart, see an object's silhouette against different backgrounds, which
  on the real nuScenes key frame made them no better than chance for two
  of six cameras (measured when this was written, 2026-11).
* :func:`overlap_consistency`, per pair of cameras: a LiDAR point seen by
  two cameras is one surface, so the two images' brightness at its two
  projections should agree. The score is Spearman's rank correlation of
  the two brightnesses over the shared points (ranks, as the cameras'
  exposures differ). A swapped camera, or an extrinsic that looks the
  wrong way, compares two different surfaces.

Scan lines are found in the image (points grouped into thin image rows and
sorted by column), so a LiDAR without ring index is checked alike.
"""
from typing import Dict, Sequence

import cv2
import numpy as np
from scipy.stats import spearmanr

#: A reflectivity edge: one return is brighter than ``RATIO`` times the
#: other plus ``OFFSET`` (the LiDAR's intensity units).
INTENSITY_RATIO, INTENSITY_OFFSET = 3.0, 5.0
#: Height of the image rows that group the points (share of the image
#: height), and the widest column gap (share of the width) between two
#: points that count as neighbours.
ROW_SHARE, GAP_SHARE = 0.01, 0.02
#: Sideways moves (shares of the width) that give the chance level.
CHANCE_SHIFTS = (-0.08, -0.05, -0.03, 0.03, 0.05, 0.08)
#: Fewer edge points (shared points) than this: no score.
MIN_EDGE_POINTS, MIN_SHARED_POINTS = 30, 20


def _brightness(image: np.ndarray) -> np.ndarray:
    """Grey levels, lightly blurred. Shape (H, W), float32."""
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float32)
    return cv2.GaussianBlur(gray, (0, 0), max(1.0, image.shape[1] / 800))


def edge_map(image: np.ndarray) -> np.ndarray:
    """Intensity edge strength (gradient magnitude, lightly blurred).

    Args:
        image (np.ndarray): RGB, Shape (H, W, 3), uint8.

    Returns:
        np.ndarray: float32. Shape (H, W).
    """
    gray = _brightness(image)
    return np.hypot(cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=3),
                    cv2.Sobel(gray, cv2.CV_32F, 0, 1, ksize=3))


def reflectivity_edges(u: np.ndarray, v: np.ndarray,
                       intensity: np.ndarray, width: int,
                       height: int) -> np.ndarray:
    """Which projected points have a much brighter or darker neighbour on
    their scan line.

    Args:
        u (np.ndarray): Column of every point, pixels. Shape (P,).
        v (np.ndarray): Row of every point, pixels. Shape (P,).
        intensity (np.ndarray): LiDAR intensity. Shape (P,).
        width (int): Image width.
        height (int): Image height.

    Returns:
        np.ndarray: bool. Shape (P,).
    """
    edge = np.zeros(len(u), bool)
    if len(u) < 2:
        return edge
    row = np.floor(v / max(1.0, ROW_SHARE * height)).astype(np.int64)
    order = np.lexsort((u, row))
    r, cols, value = row[order], u[order], intensity[order]
    neighbour = (r[1:] == r[:-1]) & (np.abs(cols[1:] - cols[:-1]) <
                                     GAP_SHARE * width)
    low = np.minimum(value[1:], value[:-1])
    high = np.maximum(value[1:], value[:-1])
    jump = neighbour & (high > INTENSITY_RATIO * low + INTENSITY_OFFSET)
    hit = np.zeros(len(u), bool)
    hit[:-1] |= jump
    hit[1:] |= jump
    edge[order] = hit
    return edge


def edge_alignment(image: np.ndarray, u: np.ndarray, v: np.ndarray,
                   intensity: np.ndarray) -> Dict[str, float]:
    """The edge-alignment score of one camera (see the module doc).

    Args:
        image (np.ndarray): RGB, Shape (H, W, 3), uint8.
        u (np.ndarray): Columns of the points inside the image. Shape (P,).
        v (np.ndarray): Their rows. Shape (P,).
        intensity (np.ndarray): Their LiDAR intensities. Shape (P,).

    Returns:
        dict[str, float]: ``edge_points`` (their count) and
        ``edge_alignment`` (NaN with fewer than :data:`MIN_EDGE_POINTS`).
    """
    height, width = image.shape[:2]
    edge = reflectivity_edges(u, v, intensity, width, height)
    count = int(edge.sum())
    out = dict(edge_points=float(count), edge_alignment=float('nan'))
    if count < MIN_EDGE_POINTS:
        return out
    strength = edge_map(image)
    cols = np.floor(u[edge]).astype(np.int64)
    rows = np.floor(v[edge]).astype(np.int64)
    aligned = strength[rows, cols].mean()
    chance = []
    for shift in CHANCE_SHIFTS:
        moved = cols + int(round(shift * width))
        inside = (moved >= 0) & (moved < width)
        if inside.any():
            chance.append(strength[rows[inside], moved[inside]].mean())
    level = float(np.mean(chance)) if chance else 0.0
    if level > 0:
        out['edge_alignment'] = float(aligned / level)
    return out


def overlap_consistency(first: np.ndarray, second: np.ndarray,
                        first_uv: Sequence[np.ndarray],
                        second_uv: Sequence[np.ndarray]) -> Dict[str, float]:
    """Spearman's correlation of two images' brightness at the two
    projections of the points both see.

    Args:
        first (np.ndarray): RGB image, Shape (H1, W1, 3), uint8.
        second (np.ndarray): RGB image, Shape (H2, W2, 3), uint8.
        first_uv (Sequence[np.ndarray]): ``(u, v)`` of the shared points
            in ``first``, each Shape (P,).
        second_uv (Sequence[np.ndarray]): Their ``(u, v)`` in ``second``.

    Returns:
        dict[str, float]: ``overlap_points`` and ``overlap_consistency``
        (NaN with fewer than :data:`MIN_SHARED_POINTS` points or a
        constant image).
    """
    count = len(first_uv[0])
    out = dict(overlap_points=float(count),
               overlap_consistency=float('nan'))
    if count < MIN_SHARED_POINTS:
        return out
    a = _brightness(first)[np.floor(first_uv[1]).astype(np.int64),
                           np.floor(first_uv[0]).astype(np.int64)]
    b = _brightness(second)[np.floor(second_uv[1]).astype(np.int64),
                            np.floor(second_uv[0]).astype(np.int64)]
    if a.std() > 0 and b.std() > 0:
        out['overlap_consistency'] = float(spearmanr(a, b).correlation)
    return out
