"""The first estimate of the pose chain: dead reckoning of the steps, turned onto the GNSS course and moved onto
the fixes. Only the starting point of the factor-graph solve depends on it."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.fusion._inputs import Problem
from pdr.schema import wrap_rad


def dead_reckoning_poses(problem: Problem, length_m: np.ndarray, dtheta_rad: np.ndarray,
                         start: tuple[float, float, float]) -> np.ndarray:
    """(N + 1, 3) poses ``e, n, heading`` of the step chain from ``start``: each step along the new heading."""
    heading = start[2] + np.concatenate([[0.0], np.cumsum(dtheta_rad)])
    e = start[0] + np.concatenate([[0.0], np.cumsum(length_m * np.cos(heading[1:]))])
    n = start[1] + np.concatenate([[0.0], np.cumsum(length_m * np.sin(heading[1:]))])
    return np.column_stack([e, n, heading])


def interpolate_positions(poses: np.ndarray, k: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    if len(poses) == 1:
        return np.repeat(poses[:1, :2], len(k), axis=0)
    return (1.0 - alpha)[:, None] * poses[k, :2] + alpha[:, None] * poses[k + 1, :2]


def align_to_fixes(poses: np.ndarray, problem: Problem) -> np.ndarray:
    """Rigidly move a dead-reckoned chain onto the GNSS fixes (2-D Procrustes, twice, dropping the worst third of
    the fixes the second time so that outliers do not set the start); only the initial estimate depends on this."""
    pos = interpolate_positions(poses, problem.gnss_k, problem.gnss_alpha)
    z = problem.gnss_en_m
    keep = np.ones(len(z), bool)
    rot, shift = np.eye(2), np.zeros(2)
    for _ in range(2):
        p, q = pos[keep], z[keep]
        pc, qc = p.mean(axis=0), q.mean(axis=0)
        if len(p) >= 2 and np.ptp(p, axis=0).max() > 5.0 and np.ptp(q, axis=0).max() > 5.0:
            u, _, vt = np.linalg.svd((p - pc).T @ (q - qc))
            d = np.sign(np.linalg.det(vt.T @ u.T))
            rot = vt.T @ np.diag([1.0, d]) @ u.T
        shift = qc - rot @ pc
        resid = np.linalg.norm(pos @ rot.T + shift - z, axis=1)
        if len(z) >= 6:
            keep = resid <= np.quantile(resid, 0.67)
    out = poses.copy()
    out[:, :2] = poses[:, :2] @ rot.T + shift
    out[:, 2] = poses[:, 2] + np.arctan2(rot[1, 0], rot[0, 0])
    return out


def along_track(poses: np.ndarray) -> np.ndarray:
    """(N,) length of each step of a chain of poses along its new heading (m)."""
    d = np.diff(poses[:, :2], axis=0)
    return d[:, 0] * np.cos(poses[1:, 2]) + d[:, 1] * np.sin(poses[1:, 2])


def course_correction(poses: np.ndarray, problem: Problem, window_s: float = 30.0) -> tuple[np.ndarray, float] | None:
    """Heading correction of a dead-reckoned chain from the GNSS course: over windows of ``window_s`` the angle between
    the fixes' displacement and the chain's, median-filtered over 5 windows (robust to outliers) and unwrapped.
    Returns the correction at every epoch and its slope (rad/s, minus the mean heading-rate bias), or None when
    fewer than 3 windows qualify. Only the initial estimate depends on this."""
    t, z = problem.gnss_t_s, problem.gnss_en_m
    p = interpolate_positions(poses, problem.gnss_k, problem.gnss_alpha)
    if len(t) < 2:
        return None
    j = np.arange(len(t))
    j2 = np.searchsorted(t, t + window_s)
    ok = (j2 < len(t)) & (j % 5 == 0)
    j, j2 = j[ok], j2[ok]
    dz, dp = z[j2] - z[j], p[j2] - p[j]
    ok = (np.linalg.norm(dz, axis=1) > 10.0) & (np.linalg.norm(dp, axis=1) > 10.0) & (t[j2] - t[j] < 3.0 * window_s)
    if ok.sum() < 3:
        return None
    angle = wrap_rad(np.arctan2(dz[ok, 1], dz[ok, 0]) - np.arctan2(dp[ok, 1], dp[ok, 0]))
    angle = np.unwrap(angle)
    angle = pd.Series(angle).rolling(5, center=True, min_periods=1).median().to_numpy()
    t_mid = 0.5 * (t[j[ok]] + t[j2[ok]])
    slope = float(np.polyfit(t_mid, angle, 1)[0])
    return np.interp(problem.epoch_t_s, t_mid, angle), slope
