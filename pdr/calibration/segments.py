"""GNSS walking segments: "GPS distance / number of steps" measurements of the mean step length (Ladetto et al. 2000).

A segment runs from one usable GNSS fix A to a later one B of the same walking bout. Its measurement is the chord
|p_B - p_A| divided by the number of steps walked between the two fix times (fractional at both ends, from the step
instants) times the straightness of the walked path: the mean resultant length of the steps' unit heading vectors,
so a corner inside a segment does not shorten the measured step (1 when the steps carry no heading).

Gates (the reason of a rejection is kept): only fixes with a finite position, a reported 1-sigma horizontal
accuracy ``h_acc_m`` of at most ``max_h_acc_m`` and in line with their neighbours (no unreported jump) end segments; both fixes must lie inside one bout of detected steps
(walking the whole time); at least ``min_segment_steps`` steps; straightness at least ``min_straightness``; and the
measured step inside ``[min_step_m, max_step_m]``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.errors import InputError

SEGMENT_COLUMNS = ("t_start_s", "t_end_s", "n_steps", "distance_m", "straightness", "h_acc_m", "measured_step_m",
                   "k_first", "k_last", "used", "reason")
DISTANCE_COLUMNS = ("t_start_s", "t_end_s", "distance_m", "distance_std_m")


def _check_steps(steps: pd.DataFrame) -> None:
    if not isinstance(steps, pd.DataFrame) or "t_s" not in steps.columns:
        raise InputError(f"calibration: expected a steps table with t_s, found "
                         f"{', '.join(map(str, getattr(steps, 'columns', []))) or type(steps).__name__}")
    t = steps["t_s"].to_numpy(float)
    if not np.isfinite(t).all() or (len(t) > 1 and (np.diff(t) <= 0).any()):
        raise InputError("calibration: expected steps t_s finite and strictly increasing, found NaN or unsorted times")


def check_gnss(gnss: pd.DataFrame) -> pd.DataFrame:
    """The GNSS table in the local frame: ``t_s, e_m, n_m, h_acc_m`` (NaN rows = invalid fixes)."""
    if not isinstance(gnss, pd.DataFrame):
        raise InputError(f"calibration: expected GNSS as a DataFrame with t_s, e_m, n_m, found {type(gnss).__name__}")
    missing = [c for c in ("t_s", "e_m", "n_m") if c not in gnss.columns]
    if missing:
        raise InputError(f"calibration: expected GNSS columns t_s, e_m, n_m (local east/north, m), found "
                         f"{', '.join(map(str, gnss.columns))}")
    t = gnss["t_s"].to_numpy(float)
    if not np.isfinite(t).all() or (len(t) > 1 and (np.diff(t) <= 0).any()):
        raise InputError("calibration: expected GNSS t_s finite and strictly increasing, found NaN or unsorted times")
    h = gnss["h_acc_m"].to_numpy(float) if "h_acc_m" in gnss.columns else np.full(len(t), np.nan)
    if (h[np.isfinite(h)] <= 0).any():
        raise InputError("calibration: expected GNSS h_acc_m > 0 (1-sigma horizontal accuracy, m), found a value <= 0")
    return pd.DataFrame({"t_s": t, "e_m": gnss["e_m"].to_numpy(float), "n_m": gnss["n_m"].to_numpy(float), "h_acc_m": h})


def clean_fixes(t_s: np.ndarray, e_m: np.ndarray, n_m: np.ndarray, h_acc_m: np.ndarray, good: np.ndarray, *,
                outlier_h_acc_factor: float, smoothing_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drop outliers and smooth: returns (usable mask, east, north).

    A fix farther than ``outlier_h_acc_factor * h_acc_m`` from the line through its two usable neighbours (each within
    3 s) is an outlier (a multipath jump the receiver did not report). Each remaining fix is replaced by a local
    straight-line fit over the usable fixes within +-``smoothing_s`` (when there are at least 3), which averages the
    white part of the GNSS error; sparse fixes (landmarks) stay as they are.
    """
    usable = good.copy()
    idx = np.flatnonzero(good)
    if len(idx) >= 3:
        prev, mid, nxt = idx[:-2], idx[1:-1], idx[2:]
        close = (t_s[nxt] - t_s[prev]) <= 3.0
        w = (t_s[mid] - t_s[prev]) / (t_s[nxt] - t_s[prev])
        de = e_m[mid] - (e_m[prev] + w * (e_m[nxt] - e_m[prev]))
        dn = n_m[mid] - (n_m[prev] + w * (n_m[nxt] - n_m[prev]))
        usable[mid[close & (np.hypot(de, dn) > outlier_h_acc_factor * h_acc_m[mid])]] = False
    e_s, n_s = e_m.copy(), n_m.copy()
    idx = np.flatnonzero(usable)
    if smoothing_s > 0 and len(idx) >= 3:
        tu = t_s[idx]
        lo = np.searchsorted(tu, tu - smoothing_s, side="left")
        hi = np.searchsorted(tu, tu + smoothing_s, side="right")
        for j, (a, b) in enumerate(zip(lo, hi)):
            if b - a >= 3:
                dt = tu[a:b] - tu[j]
                design = np.column_stack([np.ones(b - a), dt])
                coef, *_ = np.linalg.lstsq(design, np.column_stack([e_m[idx[a:b]], n_m[idx[a:b]]]), rcond=None)
                e_s[idx[j]], n_s[idx[j]] = coef[0]
    return usable, e_s, n_s


def gnss_segments(steps: pd.DataFrame, gnss: pd.DataFrame, *, segment_steps: float, min_segment_steps: float,
                  max_h_acc_m: float, assumed_h_acc_m: float, min_straightness: float, min_step_m: float,
                  max_step_m: float, outlier_h_acc_factor: float = 5.0, smoothing_s: float = 2.0) -> pd.DataFrame:
    """One row per candidate segment (columns :data:`SEGMENT_COLUMNS`); ``used`` marks those that passed the gates.

    ``k_first``/``k_last`` are the indices (into ``steps``) of the first and last step contact inside the segment.
    Fixes without ``h_acc_m`` are taken at ``assumed_h_acc_m``; outliers are dropped and fixes smoothed first
    (:func:`clean_fixes`).
    """
    _check_steps(steps)
    gnss = check_gnss(gnss)
    empty = pd.DataFrame({c: pd.Series(dtype=float) for c in SEGMENT_COLUMNS})
    if len(steps) < 2 or len(gnss) < 2:
        return empty
    t_step = steps["t_s"].to_numpy(float)
    bout = steps["bout_id"].to_numpy() if "bout_id" in steps.columns else np.zeros(len(steps), int)
    heading = steps["heading_rad"].to_numpy(float) if "heading_rad" in steps.columns else np.full(len(steps), np.nan)
    h_acc = gnss["h_acc_m"].fillna(assumed_h_acc_m).to_numpy(float)
    finite = np.isfinite(gnss["e_m"].to_numpy()) & np.isfinite(gnss["n_m"].to_numpy())
    tg, eg, ng = gnss["t_s"].to_numpy(float), gnss["e_m"].to_numpy(float), gnss["n_m"].to_numpy(float)
    good, eg, ng = clean_fixes(tg, eg, ng, h_acc, finite & (h_acc <= max_h_acc_m),
                               outlier_h_acc_factor=outlier_h_acc_factor, smoothing_s=smoothing_s)

    # bout spans and the continuous step count c(t) inside each bout
    rows = []
    bout_change = np.flatnonzero(np.diff(bout) != 0) + 1
    for lo, hi in zip(np.r_[0, bout_change], np.r_[bout_change, len(bout)]):
        if hi - lo < 2:
            continue
        t0, t1 = t_step[lo], t_step[hi - 1]
        idx = np.flatnonzero(good & (tg >= t0) & (tg <= t1))
        if len(idx) < 2:
            continue
        count = np.interp(tg[idx], t_step[lo:hi], np.arange(hi - lo, dtype=float))
        a = 0
        while a < len(idx) - 1:
            # the first fix at least segment_steps after A (or the last one of the bout)
            after = np.flatnonzero(count[a + 1:] - count[a] >= segment_steps)
            b = a + 1 + (after[0] if len(after) else len(idx) - 2 - a)
            ia, ib = idx[a], idx[b]
            n = count[b] - count[a]
            k_first = lo + int(np.floor(count[a])) + 1
            k_last = lo + int(np.floor(count[b]))
            hd = heading[k_first:k_last + 1]
            if len(hd) and np.isfinite(hd).all():
                straight = float(np.abs(np.exp(1j * hd).mean()))
            else:
                straight = 1.0
            dist = float(np.hypot(eg[ib] - eg[ia], ng[ib] - ng[ia]))
            meas = dist / (n * straight) if n > 0 and straight > 0 else np.nan
            if n >= min_segment_steps and straight < min_straightness:
                reason = f"not straight ({straight:.2f} < {min_straightness:g})"
            else:
                reason = _step_gate(n, meas, min_segment_steps, min_step_m, max_step_m)
            rows.append((tg[ia], tg[ib], n, dist, straight, float(np.sqrt((h_acc[ia] ** 2 + h_acc[ib] ** 2) / 2)),
                         meas, k_first, k_last, reason == "", reason))
            a = b
    if not rows:
        return empty
    out = pd.DataFrame(rows, columns=list(SEGMENT_COLUMNS))
    return out.astype({"k_first": int, "k_last": int, "used": bool})


def _step_gate(n_steps: float, step_m: float, min_segment_steps: float, min_step_m: float, max_step_m: float) -> str:
    """Why a segment of ``n_steps`` steps measuring ``step_m`` per step is not used ("" when it is)."""
    if n_steps < min_segment_steps:
        return f"fewer than {min_segment_steps:g} steps"
    if not (min_step_m <= step_m <= max_step_m):
        return f"implausible step {step_m:.2f} m"
    return ""


def distance_segments(steps: pd.DataFrame, distances: pd.DataFrame, *, min_segment_steps: float, min_step_m: float,
                      max_step_m: float) -> pd.DataFrame:
    """Segments of known walked distance (a measured corridor, a track lap, surveyed landmarks passed in turn): one
    row per row of ``distances`` (``t_start_s, t_end_s, distance_m, distance_std_m``; NaN times = the whole
    recording, every detected step), in the columns of :data:`SEGMENT_COLUMNS` plus ``distance_std_m``.

    The steps of a segment are those whose contact falls in ``(t_start_s, t_end_s]``, fractional at both ends (the
    step count interpolated in time between contacts); the same gates on steps and measured step as
    :func:`gnss_segments`, no straightness (the distance is the path walked).
    """
    _check_steps(steps)
    missing = [c for c in DISTANCE_COLUMNS if c not in distances.columns]
    if missing:
        raise InputError(f"calibration: expected distance columns {', '.join(DISTANCE_COLUMNS)}, missing {', '.join(missing)}")
    t_step = steps["t_s"].to_numpy(float)
    n_all = len(t_step)
    rows = []
    for r in distances.itertuples(index=False):
        dist, std = float(r.distance_m), float(r.distance_std_m)
        if not (np.isfinite(dist) and dist > 0 and np.isfinite(std) and std > 0):
            raise InputError(f"calibration: expected a known distance > 0 m with a std > 0, found {dist} m +- {std} m")
        if np.isnan(r.t_start_s) and np.isnan(r.t_end_s):
            n, k_first, k_last = float(n_all), 0, n_all - 1
            t0, t1 = (float(t_step[0]), float(t_step[-1])) if n_all else (np.nan, np.nan)
        else:
            t0, t1 = float(r.t_start_s), float(r.t_end_s)
            count = np.interp([t0, t1], t_step, np.arange(n_all, dtype=float)) if n_all >= 2 else np.zeros(2)
            n = float(count[1] - count[0])
            k_first, k_last = int(np.floor(count[0])) + 1, int(np.floor(count[1]))
        meas = dist / n if n > 0 else np.nan
        reason = _step_gate(n, meas, min_segment_steps, min_step_m, max_step_m)
        rows.append((t0, t1, n, dist, 1.0, np.nan, meas, k_first, k_last, reason == "", reason, std))
    out = pd.DataFrame(rows, columns=[*SEGMENT_COLUMNS, "distance_std_m"])
    return out.astype({"k_first": int, "k_last": int, "used": bool})


def landmark_distances(landmarks: pd.DataFrame, position_std_m: float) -> pd.DataFrame:
    """Known distances between consecutive surveyed landmarks (``t_s, e_m, n_m``: the time each was passed), walked
    in a straight line: the table of :func:`distance_segments`, each distance known to ``sqrt(2)`` x the position
    error of a landmark passing."""
    missing = [c for c in ("t_s", "e_m", "n_m") if c not in landmarks.columns]
    if missing:
        raise InputError(f"calibration: expected landmarks columns t_s, e_m, n_m, missing {', '.join(missing)}")
    lm = landmarks.sort_values("t_s")
    t, e, n = (lm[c].to_numpy(float) for c in ("t_s", "e_m", "n_m"))
    return pd.DataFrame({"t_start_s": t[:-1], "t_end_s": t[1:], "distance_m": np.hypot(np.diff(e), np.diff(n)),
                         "distance_std_m": np.sqrt(2.0) * position_std_m})


def trajectory_distances(trajectory: pd.DataFrame, segment_s: float, position_std_m: float) -> pd.DataFrame:
    """Known distances from a reference trajectory (``t_s, e_m, n_m``): its path length over consecutive windows of
    ``segment_s``, each known to ``sqrt(2)`` x ``position_std_m``."""
    missing = [c for c in ("t_s", "e_m", "n_m") if c not in trajectory.columns]
    if missing:
        raise InputError(f"calibration: expected trajectory columns t_s, e_m, n_m, missing {', '.join(missing)}")
    t, e, n = (trajectory[c].to_numpy(float) for c in ("t_s", "e_m", "n_m"))
    ok = np.isfinite(t) & np.isfinite(e) & np.isfinite(n)
    t, e, n = t[ok], e[ok], n[ok]
    if len(t) < 2:
        return pd.DataFrame({c: pd.Series(dtype=float) for c in DISTANCE_COLUMNS})
    path = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(e), np.diff(n)))])
    edges = np.arange(t[0], t[-1] + 1e-9, segment_s)
    if edges[-1] < t[-1]:
        edges = np.append(edges, t[-1])
    s_at = np.interp(edges, t, path)
    return pd.DataFrame({"t_start_s": edges[:-1], "t_end_s": edges[1:], "distance_m": np.diff(s_at),
                         "distance_std_m": np.sqrt(2.0) * position_std_m})
