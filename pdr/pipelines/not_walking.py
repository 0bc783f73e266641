"""What is not walking: a vehicle, a bicycle, or a recording too slow for steps, found with the GNSS.

A person on foot covers at most one step length per step: over a window of ``WINDOW_S``, the distance the GNSS
surely covered (the displacement between the medians of the first and last ``MEDIAN_FIXES`` fixes, less
``SPEED_SIGMAS`` times their accuracies) can not exceed ``MAX_STEP_M`` (the longest step any step model yields; a
sprint step is ~1.5 m) times the steps found in it, nor the fastest speed of a person on foot for the body. The
running limit is a Froude number ``v^2 / (g L) = MAX_FROUDE`` with leg length ``L = 0.53 * height`` (Winter,
*Biomechanics and Motor Control of Human Movement*, segment proportions): Froude 4 is 6.1 m/s for a 1.75 m person,
a fast amateur run (the walk-run transition is Froude 0.5, Alexander 1989). Above Froude 1 (3 m/s) no one walks (the inverted pendulum would leave the ground):
a person on foot runs, and running has flight phases (specific force under 0.25 g) and impacts over 1 g at every
step, a step-window variance of |a| of at least ``(MIN_RUN_ACC_STD_G g)^2``; "steps" found without it are the
pedalling or the bounce of a bicycle or a car (no gait periodicity). Windows that break any bound are not walking;
runs of ``MIN_FLAGGED_WINDOWS`` of them (starting at consecutive fixes) merge into intervals where less than a window apart;
those lasting ``MIN_INTERVAL_S`` lose their steps, with a warning.

Below ``2 * MAX_CADENCE_HZ`` samples per second a step's impact can not be told from the next one (Nyquist): no step
is looked for, and the run follows the GNSS alone.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from pdr.constants import GRAVITY_MPS2
from pdr.step_length.models import MAX_STEP_M

WINDOW_S = 8.0  # about 14 steps: long enough that a 5 m fix error is a small part of a vehicle's distance
SPEED_SIGMAS = 2.0
DEFAULT_H_ACC_M = 5.0  # a phone fix without an accuracy
MIN_MOVING_MPS = 0.5  # a window without steps that moves slower than this is GNSS noise about a standing person
MAX_FROUDE = 4.0
MEDIAN_FIXES = 3  # each window's ends: the median of 3 fixes (an outlying fix moves no median)
MIN_FLAGGED_WINDOWS = 3  # consecutive windows: a single outlying fix flags only windows that do not follow each other
MIN_INTERVAL_S = 3 * WINDOW_S  # a merged interval at least this long: outlying fixes flag short ones (10% of fixes
# 50 m off: one of 16 s in 2 x 30 min), a ride lasts minutes
RUN_ONLY_FROUDE = 1.0
MIN_RUN_ACC_STD_G = 0.25
LEG_PER_HEIGHT = 0.53
DEFAULT_HEIGHT_M = 1.75
SMOOTH_S = 10.0  # the GNSS-only trajectory: fixes averaged over this window
MAX_CADENCE_HZ = 3.5  # the fastest running cadence the step detectors look for (``max_step_freq_hz``)


def min_step_rate_hz() -> float:
    """The lowest IMU sampling rate at which steps can be found: twice the highest cadence."""
    return 2.0 * MAX_CADENCE_HZ


def froude_speed_mps(froude: float, height_m: float | None) -> float:
    """The speed on foot at Froude number ``froude`` for the body."""
    leg = LEG_PER_HEIGHT * (height_m if height_m else DEFAULT_HEIGHT_M)
    return float(np.sqrt(froude * GRAVITY_MPS2 * leg))


def not_walking_intervals(steps: pd.DataFrame, gnss: pd.DataFrame | None, height_m: float | None) -> list[dict[str, Any]]:
    """``[{t_start_s, t_end_s, speed_mps, n_steps, reason}]``: the stretches the GNSS shows to be no walk.

    ``steps`` is the steps table (``t_s``, ``acc_var_m2ps4``); ``gnss`` the local table of ``run.gnss_local``
    (``t_s, e_m, n_m, h_acc_m, masked``)."""
    if gnss is None:
        return []
    ok = np.isfinite(gnss["e_m"].to_numpy(float)) & np.isfinite(gnss["n_m"].to_numpy(float)) & ~gnss["masked"].to_numpy(bool)
    g = gnss[ok]
    t, e, n = g["t_s"].to_numpy(float), g["e_m"].to_numpy(float), g["n_m"].to_numpy(float)
    h = np.where(np.isfinite(g["h_acc_m"].to_numpy(float)), g["h_acc_m"].to_numpy(float), DEFAULT_H_ACC_M)
    if len(t) < 2:
        return []
    v_foot, v_run = froude_speed_mps(MAX_FROUDE, height_m), froude_speed_mps(RUN_ONLY_FROUDE, height_m)
    order = np.argsort(steps["t_s"].to_numpy(float), kind="stable")
    step_t_s = steps["t_s"].to_numpy(float)[order]
    acc_var = steps["acc_var_m2ps4"].to_numpy(float)[order] if "acc_var_m2ps4" in steps else np.full(len(order), np.inf)
    min_run_var = (MIN_RUN_ACC_STD_G * GRAVITY_MPS2) ** 2
    flagged: list[tuple[int, float, float, float, str]] = []
    j = 0
    for i in range(len(t)):
        j = max(j, i + 1)
        while j < len(t) and t[j] - t[i] < WINDOW_S:
            j += 1
        if j >= len(t):
            break
        dt = t[j] - t[i]
        if dt > 2 * WINDOW_S:  # a GNSS outage: the window says nothing about speed
            continue
        a, b = slice(i, min(i + MEDIAN_FIXES, j)), slice(max(j - MEDIAN_FIXES + 1, i + 1), j + 1)
        d = float(np.hypot(np.median(e[b]) - np.median(e[a]), np.median(n[b]) - np.median(n[a])))
        sure = max(0.0, d - SPEED_SIGMAS * float(np.hypot(np.median(h[a]), np.median(h[b]))))
        v = sure / max(float(np.median(t[b]) - np.median(t[a])), 1e-9)  # the time between the medians
        lo, hi = int(np.searchsorted(step_t_s, t[i], side="left")), int(np.searchsorted(step_t_s, t[j], side="right"))
        k = hi - lo
        if v > v_foot:
            flagged.append((i, t[i], t[j], v, f"faster than {v_foot:.1f} m/s on foot"))
        elif v > MIN_MOVING_MPS and sure > MAX_STEP_M * k:
            reason = (f"{k} steps would be {sure / k:.1f} m long (at most {MAX_STEP_M:g} m)" if k
                      else "moving without steps")
            flagged.append((i, t[i], t[j], v, reason))
        elif v > v_run and k and float(np.nanmedian(acc_var[lo:hi])) < min_run_var:
            flagged.append((i, t[i], t[j], v, f"steps without the impacts of running above {v_run:.1f} m/s"))
    runs: list[list[tuple[int, float, float, float, str]]] = []
    for f in flagged:  # a run of windows starting at consecutive fixes: one outlying fix flags no run
        if runs and f[0] == runs[-1][-1][0] + 1:
            runs[-1].append(f)
        else:
            runs.append([f])
    intervals: list[dict[str, Any]] = []
    for run in (r for r in runs if len(r) >= MIN_FLAGGED_WINDOWS):
        a, b, v = run[0][1], max(f[2] for f in run), max(f[3] for f in run)
        if intervals and a <= intervals[-1]["t_end_s"] + WINDOW_S:  # one window short of flagged is still the ride
            intervals[-1]["t_end_s"] = max(intervals[-1]["t_end_s"], b)
            intervals[-1]["speed_mps"] = max(intervals[-1]["speed_mps"], v)
            continue
        intervals.append({"t_start_s": float(a), "t_end_s": float(b), "speed_mps": float(v), "reason": run[0][4]})
    intervals = [iv for iv in intervals if iv["t_end_s"] - iv["t_start_s"] >= MIN_INTERVAL_S]
    for iv in intervals:
        inside = (step_t_s >= iv["t_start_s"]) & (step_t_s <= iv["t_end_s"])
        iv["n_steps"] = int(inside.sum())
    return intervals


def drop_not_walking(steps: pd.DataFrame, intervals: list[dict[str, Any]]) -> pd.DataFrame:
    """``steps`` without the rows inside any interval."""
    t = steps["t_s"].to_numpy(float)
    keep = np.ones(len(t), bool)
    for iv in intervals:
        keep &= ~((t >= iv["t_start_s"]) & (t <= iv["t_end_s"]))
    return steps[keep].reset_index(drop=True)


def interval_message(rec_id: str, iv: dict[str, Any]) -> str:
    return (f"{rec_id}: not walking from t = {iv['t_start_s']:.1f} to {iv['t_end_s']:.1f} s (GNSS at least "
            f"{iv['speed_mps']:.1f} m/s: {iv['reason']}, a vehicle or a bicycle?); its {iv['n_steps']} detected step(s) "
            "dropped, no steps there")


def gnss_only_trajectory(gnss: pd.DataFrame, used: np.ndarray) -> pd.DataFrame | None:
    """The trajectory of a run without steps: the usable fixes averaged (weights 1/h_acc²) over ``SMOOTH_S``
    centred on each, the heading of the smoothed track between them (None with fewer than 2 usable fixes).

    Raw fixes zigzag by their noise (1.5 m at 1 Hz nearly triples a walk's length); over ``SMOOTH_S`` a walker's
    velocity changes little, so the mean is the path less the noise (corners are rounded by a few metres)."""
    g = gnss[used]
    if len(g) < 2:
        return None
    t, e, n = g["t_s"].to_numpy(float), g["e_m"].to_numpy(float), g["n_m"].to_numpy(float)
    h = np.where(np.isfinite(g["h_acc_m"].to_numpy(float)), g["h_acc_m"].to_numpy(float), DEFAULT_H_ACC_M)
    w = 1.0 / np.maximum(h, 0.1) ** 2
    lo = np.searchsorted(t, t - SMOOTH_S / 2, side="left")
    hi = np.searchsorted(t, t + SMOOTH_S / 2, side="right")
    cw, ce, cn = (np.concatenate([[0.0], np.cumsum(x)]) for x in (w, w * e, w * n))
    sw = cw[hi] - cw[lo]
    e_s, n_s = (ce[hi] - ce[lo]) / sw, (cn[hi] - cn[lo]) / sw
    std = 1.0 / np.sqrt(sw)
    heading = np.arctan2(np.diff(n_s), np.diff(e_s))
    heading = np.concatenate([heading, heading[-1:]])
    return pd.DataFrame({"t_s": t, "e_m": e_s, "n_m": n_s, "heading_rad": heading, "e_std_m": std, "n_std_m": std})
