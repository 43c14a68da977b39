"""Box-frame alignment: annotated objects' points in their own frames.

A moving car's points, accumulated in the world frame over a few seconds,
smear along its path. In the frame of its box (origin at the box centre,
x along the heading) they stay put, so a whole sequence of sweeps
accumulates into one dense object that can be placed at its box of any
key frame.

nuScenes annotates boxes at key frames only (2 Hz); the pose at a sweep
between two key frames is interpolated linearly (centre and yaw), and
before the first or after the last annotation it is extrapolated with the
velocity of the nearest annotated interval for at most
``max_extrapolation`` seconds (an instance annotated once is held still
as long). Outside that window the instance has no box: its points stay
with the static scene, where free-space carving removes what moved.
"""
from typing import List, Tuple

import numpy as np

from .sequence import Track


def _wrap(angle: np.ndarray) -> np.ndarray:
    return np.arctan2(np.sin(angle), np.cos(angle))


def track_poses(track: Track, times: np.ndarray,
                max_extrapolation: float) -> Tuple[np.ndarray, np.ndarray,
                                                   np.ndarray]:
    """The box of one instance at given times.

    Args:
        track (Track): The instance's annotated boxes.
        times (np.ndarray): Seconds. Shape (T,).
        max_extrapolation (float): Seconds a box is extrapolated beyond
            the first and last annotation.

    Returns:
        tuple[np.ndarray, np.ndarray, np.ndarray]: Centres (Shape (T, 3)),
        yaws (Shape (T,)) and whether the instance has a box then
        (Shape (T,), bool).
    """
    times = np.asarray(times, np.float64)
    t = track.times
    yaws = np.unwrap(track.yaws)
    valid = (times >= t[0] - max_extrapolation) & (
        times <= t[-1] + max_extrapolation)
    if len(t) == 1:
        centers = np.repeat(track.centers, len(times), axis=0)
        return centers, np.full(len(times), track.yaws[0]), valid
    # Piecewise-linear inside, the end intervals' velocity outside.
    segment = np.clip(np.searchsorted(t, times) - 1, 0, len(t) - 2)
    t0, t1 = t[segment], t[segment + 1]
    weight = ((times - t0) / (t1 - t0))[:, None]
    centers = (1 - weight) * track.centers[segment] + (
        weight * track.centers[segment + 1])
    yaw = (1 - weight[:, 0]) * yaws[segment] + weight[:, 0] * yaws[
        segment + 1]
    return centers, _wrap(yaw), valid


def to_box_frame(points: np.ndarray, center: np.ndarray,
                 yaw: float) -> np.ndarray:
    """Global points in a box's frame. Shape (N, 3)."""
    c, s = np.cos(yaw), np.sin(yaw)
    d = points - center
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1],
                     d[:, 2]], axis=1)


def from_box_frame(points: np.ndarray, center: np.ndarray,
                   yaw: float) -> np.ndarray:
    """Box-frame points in the global frame. Shape (N, 3)."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([c * points[:, 0] - s * points[:, 1],
                     s * points[:, 0] + c * points[:, 1], points[:, 2]],
                    axis=1) + center


def assign_to_boxes(points: np.ndarray, centers: np.ndarray,
                    yaws: np.ndarray, sizes: np.ndarray, margin: float,
                    ground_clearance: np.ndarray,
                    chunk: int = 32) -> Tuple[np.ndarray, np.ndarray]:
    """Which box every point lies in, and where in it.

    A box is grown by ``margin`` on its sides and top (range noise and
    annotation slack put surface points just outside it); its bottom is
    raised by a point's ``ground_clearance`` so that the ground it stands
    on stays with the static scene. A point in several grown boxes goes
    to the one whose centre is nearest.

    Args:
        points (np.ndarray): Global points. Shape (N, 3).
        centers (np.ndarray): Box centres. Shape (B, 3).
        yaws (np.ndarray): Headings. Shape (B,).
        sizes (np.ndarray): Length, width, height. Shape (B, 3).
        margin (float): Growth of the sides and top, metres.
        ground_clearance (np.ndarray): Rise of the bottom for every point,
            metres (negative: lowered). Shape (N,).
        chunk (int): Boxes tested at once (bounds memory to N x chunk).
            Defaults to 32.

    Returns:
        tuple[np.ndarray, np.ndarray]: Box index per point (-1: none),
        Shape (N,), and the box-frame coordinates of every point (those
        of its box; undefined for -1), Shape (N, 3).
    """
    num = len(points)
    owner = np.full(num, -1, dtype=np.int64)
    local = np.zeros((num, 3))
    best = np.full(num, np.inf)
    for start in range(0, len(yaws), chunk):
        c = np.cos(yaws[start:start + chunk])[None]
        s = np.sin(yaws[start:start + chunk])[None]
        d = points[:, None] - centers[None, start:start + chunk]
        x = c * d[..., 0] + s * d[..., 1]
        y = -s * d[..., 0] + c * d[..., 1]
        z = d[..., 2]
        half = sizes[None, start:start + chunk] / 2
        inside = ((np.abs(x) <= half[..., 0] + margin)
                  & (np.abs(y) <= half[..., 1] + margin)
                  & (z <= half[..., 2] + margin)
                  & (z >= -half[..., 2] + ground_clearance[:, None]))
        dist = np.where(inside, x * x + y * y + z * z, np.inf)
        nearest = np.argmin(dist, axis=1)
        rows = np.arange(num)
        closer = dist[rows, nearest] < best
        owner[closer] = start + nearest[closer]
        best[closer] = dist[rows, nearest][closer]
        local[closer] = np.stack([x, y, z], axis=-1)[rows, nearest][closer]
    return owner, local


def boxes_at(tracks: List[Track], times: np.ndarray,
             max_extrapolation: float) -> Tuple[np.ndarray, np.ndarray,
                                                np.ndarray]:
    """Every track's box at every time (a loop over instances, not
    points).

    Args:
        tracks (List[Track]): The instances (index i = track i).
        times (np.ndarray): Seconds. Shape (T,).
        max_extrapolation (float): See :func:`track_poses`.

    Returns:
        tuple[np.ndarray, np.ndarray, np.ndarray]: Centres (Shape (T, I,
        3)), yaws (Shape (T, I)) and validity (Shape (T, I), bool).
    """
    num_t = len(times)
    centers = np.zeros((num_t, len(tracks), 3))
    yaws = np.zeros((num_t, len(tracks)))
    valid = np.zeros((num_t, len(tracks)), dtype=bool)
    for i, track in enumerate(tracks):
        centers[:, i], yaws[:, i], valid[:, i] = track_poses(
            track, times, max_extrapolation)
    return centers, yaws, valid
