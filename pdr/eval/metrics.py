"""Metric functions of ``pdr evaluate``: event matching, step timing F1, path length, alignment, trajectory errors.

All positions are ``(N, 2)`` arrays of east/north metres; times in seconds.
"""

from __future__ import annotations

import numpy as np


def match_events(t_ref_s: np.ndarray, t_est_s: np.ndarray, tolerance_s: float) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one matching of two sorted event series within ``tolerance_s``; returns matched index pairs.

    Notes
    -----
    Each reference event may match one estimated event with ``|t_est - t_ref| <= tolerance_s`` and vice versa.
    The acceptance windows all have the same width, so they are ordered by start and by end alike; matching each
    reference event, in time order, to the earliest still-free estimate in its window then gives a maximum matching
    (the greedy earliest-deadline argument for interval bipartite graphs). Linear in the number of events.
    """
    t_ref = np.asarray(t_ref_s, float)
    t_est = np.asarray(t_est_s, float)
    if tolerance_s < 0:
        raise ValueError(f"tolerance_s must be >= 0, found {tolerance_s}")
    if np.any(np.diff(t_ref) < 0) or np.any(np.diff(t_est) < 0):
        raise ValueError("match_events expects sorted times")
    i_ref, i_est = [], []
    j = 0
    for i, t in enumerate(t_ref):
        while j < len(t_est) and t_est[j] < t - tolerance_s:
            j += 1
        if j < len(t_est) and t_est[j] <= t + tolerance_s:
            i_ref.append(i)
            i_est.append(j)
            j += 1
    return np.asarray(i_ref, int), np.asarray(i_est, int)


def event_f1(t_ref_s: np.ndarray, t_est_s: np.ndarray, tolerance_s: float) -> dict[str, float]:
    """Precision, recall and F1 of estimated events against reference events matched within ``tolerance_s``."""
    i_ref, _ = match_events(t_ref_s, t_est_s, tolerance_s)
    tp, n_ref, n_est = len(i_ref), len(t_ref_s), len(t_est_s)
    precision = tp / n_est if n_est else 0.0
    recall = tp / n_ref if n_ref else 0.0
    f1 = 2 * tp / (n_ref + n_est) if n_ref + n_est else 0.0
    return {"precision": precision, "recall": recall, "f1": f1, "n_matched": tp}


def path_length_m(xy: np.ndarray) -> float:
    """Length of a polyline (sum of segment lengths)."""
    xy = np.asarray(xy, float)
    if len(xy) < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1)))


def interpolate_positions(t_s: np.ndarray, xy: np.ndarray, t_query_s: np.ndarray) -> np.ndarray:
    """Positions at ``t_query_s`` by linear interpolation between poses; held constant before the first and after the last."""
    t_s, xy, tq = np.asarray(t_s, float), np.asarray(xy, float), np.asarray(t_query_s, float)
    return np.stack([np.interp(tq, t_s, xy[:, 0]), np.interp(tq, t_s, xy[:, 1])], axis=-1)


def fit_rotation_about(est_xy: np.ndarray, ref_xy: np.ndarray, anchor_est: np.ndarray, anchor_ref: np.ndarray) -> float:
    """Angle (rad, CCW) that best maps ``est - anchor_est`` onto ``ref - anchor_ref`` in the least-squares sense.

    Notes
    -----
    Closed form of the 2-D Procrustes rotation with fixed centre: ``angle = atan2(sum(a x b), sum(a . b))``.
    """
    a = np.asarray(est_xy, float) - anchor_est
    b = np.asarray(ref_xy, float) - anchor_ref
    cross = np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    dot = np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])
    if cross == 0.0 and dot == 0.0:
        return 0.0
    return float(np.arctan2(cross, dot))


def rotate_about(xy: np.ndarray, angle_rad: float, centre: np.ndarray, to: np.ndarray) -> np.ndarray:
    """Rotate points by ``angle_rad`` about ``centre``, then move ``centre`` onto ``to``."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    rot = np.array([[c, -s], [s, c]])
    return (np.asarray(xy, float) - centre) @ rot.T + to


def rmse_m(est_xy: np.ndarray, ref_xy: np.ndarray) -> float:
    err = np.linalg.norm(np.asarray(est_xy, float) - np.asarray(ref_xy, float), axis=1)
    return float(np.sqrt(np.mean(err ** 2))) if len(err) else float("nan")


def position_errors_m(est_xy: np.ndarray, ref_xy: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.asarray(est_xy, float) - np.asarray(ref_xy, float), axis=1)
