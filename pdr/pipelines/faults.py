"""Sensor faults in ``pdr run``: detect them (:class:`pdr.signals.faults.SensorFaultDetection`, configuration section
``[faults]``), widen the uncertainty of the steps they touch, keep jumped GNSS fixes out of the fusion, and list
them as ``warnings`` of ``summary.json``.

Every warning of ``summary.json`` is an object ``{"kind", "sensor", "t_start_s", "t_end_s", "message"}``: the
faults with their time range (kinds: ``gap``, ``stuck``, ``saturation``, ``duplicated_samples``, ``rate_change``,
``mag_disturbance``, ``gnss_jump``, ``gnss_rejected``), and the other warnings of the run as ``kind = "general"``
with null times and sensor.

Widening (the trajectory stays one continuous chain of poses; only the weights change):

- a step whose interval (previous contact to its contact) meets a gap, or a stuck, saturated, duplicated or
  resampled accelerometer: its length is known to ``FAULT_LENGTH_STD_FRACTION`` of a typical step (the median of the
  others) at best; a step over a gap longer than the fusion's ``max_step_duration_s`` is already a *gap step* there
  (displacement known only to a walking speed times its duration);
- ... meets a gap or a faulty gyroscope: its heading change is known to ``FAULT_HEADING_CHANGE_STD_RAD`` at best;
- ... meets a magnetic disturbance: no magnetic heading;
- GNSS fixes that jumped are not used (as if masked).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from pdr.signals.faults import SensorFaultDetection
from pdr.signals.resample import runs

FAULT_LENGTH_STD_FRACTION = 0.5  # a step length from a faulty accelerometer: +-50% (the spread of human step lengths)
FAULT_HEADING_CHANGE_STD_RAD = 0.5  # a heading change over a faulty gyroscope: about a quarter turn at 3 sigma per step
LENGTH_FAULTS = {"gap", "stuck", "saturation", "duplicated_samples", "rate_change"}
LENGTH_SENSORS = {"imu", "acc"}
HEADING_SENSORS = {"imu", "gyr"}


def sensor_faults(detector: SensorFaultDetection, imu: pd.DataFrame, gnss: pd.DataFrame | None) -> SensorFaultDetection:
    """Detect the faults of the main IMU and of the GNSS fixes (local frame, with ``masked``) with ``detector``."""
    if gnss is not None:
        gnss = gnss.assign(e_m=np.where(gnss["masked"], np.nan, gnss["e_m"]),
                           n_m=np.where(gnss["masked"], np.nan, gnss["n_m"]))
    return detector.detect(imu, gnss)


def widen_steps(steps: pd.DataFrame, faults: pd.DataFrame, t_start_s: float) -> pd.DataFrame:
    """The steps table with the uncertainty widened where a fault touches a step (see the module docstring)."""
    if len(steps) == 0 or len(faults) == 0:
        return steps
    steps = steps.copy()
    t = steps["t_s"].to_numpy(float)
    prev = np.concatenate([[min(t_start_s, t[0])], t[:-1]])

    def touched(rows: pd.DataFrame) -> np.ndarray:
        hit = np.zeros(len(t), bool)
        for a, b in zip(rows["t_start_s"], rows["t_end_s"]):
            hit |= (prev <= b) & (t >= a)
        return hit

    imu_faults = faults[faults["kind"].isin(LENGTH_FAULTS)]
    length_hit = touched(imu_faults[imu_faults["sensor"].isin(LENGTH_SENSORS)])
    if length_hit.any():
        length = steps["step_length_m"].to_numpy(float)
        std = steps["step_length_std_m"].to_numpy(float)
        # of a typical step: a faulty signal can make a signal-based model's length itself small (a stuck accelerometer
        # has no vertical excursion)
        typical = float(np.median(length[~length_hit])) if (~length_hit).any() else float(np.median(length))
        steps["step_length_std_m"] = np.where(length_hit, np.fmax(std, FAULT_LENGTH_STD_FRACTION * typical), std)
    heading_hit = touched(imu_faults[imu_faults["sensor"].isin(HEADING_SENSORS)])
    if heading_hit.any() and "heading_change_std_rad" in steps.columns:
        std = steps["heading_change_std_rad"].to_numpy(float)
        steps["heading_change_std_rad"] = np.where(heading_hit, np.fmax(std, FAULT_HEADING_CHANGE_STD_RAD), std)
    mag_hit = touched(faults[faults["kind"] == "mag_disturbance"])
    if mag_hit.any() and "mag_heading_rad" in steps.columns:
        steps.loc[mag_hit, "mag_heading_rad"] = np.nan
        steps.loc[mag_hit, "mag_heading_std_rad"] = np.nan
    return steps


def rejected_gnss(gnss: pd.DataFrame, suspect: np.ndarray, used: np.ndarray, t_first_s: float,
                  t_last_s: float) -> list[dict[str, Any]]:
    """Runs of valid, unmasked fixes within the walk (``t_first_s`` to ``t_last_s``) that the fusion's robust GNSS
    factor left out (jumps found before the fusion are reported as ``gnss_jump`` instead)."""
    t = gnss["t_s"].to_numpy(float)
    valid = np.isfinite(gnss["e_m"].to_numpy()) & np.isfinite(gnss["n_m"].to_numpy()) & ~gnss["masked"].to_numpy(bool)
    candidates = np.flatnonzero(valid & ~suspect & (t >= t_first_s) & (t <= t_last_s))
    out = []
    for a, b in runs(~used[candidates]):
        rows = candidates[a:b]
        acc = gnss["h_acc_m"].to_numpy(float)[rows]
        acc_txt = f"reporting h_acc_m {np.nanmin(acc):.1f} m or better" if np.isfinite(acc).any() else "without h_acc_m"
        out.append({"kind": "gnss_rejected", "sensor": "gnss", "t_start_s": float(t[rows[0]]), "t_end_s": float(t[rows[-1]]),
                    "message": f"{len(rows)} GNSS fix(es) {acc_txt} disagree with the steps and the other fixes; "
                               "left out by the fusion"})
    return out


def warning_objects(faults: pd.DataFrame, extra: list[dict[str, Any]], messages: list[str]) -> list[dict[str, Any]]:
    """``summary.json`` ``warnings``: the faults (sorted by time), then the run's other warnings as ``general``."""
    rows = [{"kind": str(r.kind), "sensor": str(r.sensor), "t_start_s": round(float(r.t_start_s), 6),
             "t_end_s": round(float(r.t_end_s), 6), "message": str(r.message)} for r in faults.itertuples()]
    rows += [{**e, "t_start_s": round(e["t_start_s"], 6), "t_end_s": round(e["t_end_s"], 6)} for e in extra]
    rows.sort(key=lambda w: (w["t_start_s"], w["kind"]))
    return rows + [{"kind": "general", "sensor": None, "t_start_s": None, "t_end_s": None, "message": m} for m in messages]


def warning_line(w: dict[str, Any]) -> str:
    """One stderr line for a fault warning."""
    return f"{w['kind']} ({w['sensor']}) from {w['t_start_s']:.2f} s to {w['t_end_s']:.2f} s: {w['message']}"
