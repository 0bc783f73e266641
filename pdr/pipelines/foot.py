"""Strides from shoe-mounted IMUs (``imu_foot_left.csv`` / ``imu_foot_right.csv``, or ``imu.csv`` placed on a foot).

Configuration section ``[foot]``::

    [foot]
    method = "zupt_ins"          # or "footstep_tracker"
    double_feet = true           # DoubleFeetCalibration when both feet are present (default: footstep_tracker only)
    [foot.zero_velocity]         # ZeroVelocityDetection parameters
    [foot.zupt_ins]              # ZuptInsStride parameters (foot is set here)
    [foot.footstep_tracker]      # FootStepTrackerStride parameters
    [foot.double_feet_calibration]
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError, check_keys, warn
from pdr.foot import DoubleFeetCalibration, FootStepTrackerStride, ZeroVelocityDetection, ZuptInsStride
from pdr.foot._checks import check_pair, foot_imu_arrays
from pdr.foot.footstep_tracker import empty_strides
from pdr.io.recording import Recording
from pdr.schema import STRIDE_COLUMNS
from pdr.signals.faults import clipped_samples

FOOT_SOURCE = "foot_imu"  # the strides table's source of the shoe IMUs' strides
METHODS = {"zupt_ins": ZuptInsStride, "footstep_tracker": FootStepTrackerStride}
SECTION_KEYS = {"method", "double_feet", "zero_velocity", "zupt_ins", "footstep_tracker", "double_feet_calibration"}
GYR_SATURATION_MIN_RADPS = 4.0  # 230 deg/s: below this a flat top is a resting sensor, not a clipped one
ACC_SATURATION_MIN_MPS2 = 2.0 * 9.80665
INS_COLUMNS = ["dx_m", "dy_m", "lateral_std_m", "heading_rad", "heading_change_std_rad"]
# A walking stride stays below 2 m (about 1.9 m at 2 m/s, the walk-run transition; Grieve & Gear 1966) and its swing
# takes about 40% of a gait cycle (Perry & Burnfield 2010, Gait Analysis): a longer stride, or a swing longer than
# MISSED_STANCE_SWING_RATIO times the foot's median swing (two swings and the stance between them), is not a stride.
MAX_STRIDE_M = 2.5
# A brisk walk's stance lasts about 0.1 s at mid-stance rest: the zero-velocity window (0.1 s) needs 8 samples in it
MIN_RATE_HZ = 80.0
MISSED_STANCE_SWING_RATIO = 2.0


def foot_imus(rec: Recording) -> dict[str, pd.DataFrame]:
    """The foot IMUs of a recording by foot (``"left"``, ``"right"``); empty when there is none."""
    return {placement[len("foot_"):]: imu for placement, imu in rec.imus_by_placement().items()
            if placement in ("foot_left", "foot_right")}


def _saturation(imu: pd.DataFrame, foot: str) -> np.ndarray:
    """Samples where the gyroscope or the accelerometer sits at its range (warns when any)."""
    t, acc, gyr = foot_imu_arrays(imu, f"{foot} foot IMU")
    rate = 1.0 / float(np.median(np.diff(t)))
    gyr_sat = clipped_samples(gyr, rate, min_abs=GYR_SATURATION_MIN_RADPS)
    acc_sat = clipped_samples(acc, rate, min_abs=ACC_SATURATION_MIN_MPS2)
    if gyr_sat.any():
        warn(f"{foot} foot IMU: the gyroscope is saturated (flat at {np.abs(gyr).max():.2f} rad/s) in "
             f"{int(gyr_sat.sum())} samples; strides across them are dropped")
    if acc_sat.any():
        warn(f"{foot} foot IMU: the accelerometer is saturated (flat at {np.abs(acc).max():.1f} m/s²) in "
             f"{int(acc_sat.sum())} samples; strides across them are dropped")
    return gyr_sat | acc_sat


def implausible(strides: pd.DataFrame) -> np.ndarray:
    """Reason (str, empty when plausible) of every stride of one foot that cannot be a walking stride: longer than
    ``MAX_STRIDE_M``, or a swing longer than ``MISSED_STANCE_SWING_RATIO`` times the foot's median swing (a stance
    the zero-velocity detection missed: the INS integrated two strides and more as one)."""
    length = strides["length_m"].to_numpy(float)
    reason = np.where(length > MAX_STRIDE_M, [f"{x:.2f} m is longer than a walking stride ({MAX_STRIDE_M:g} m)"
                                              for x in length], "")
    if {"t_swing_start_s", "t_swing_end_s"} <= set(strides.columns) and len(strides) >= 3:
        swing = (strides["t_swing_end_s"] - strides["t_swing_start_s"]).to_numpy(float)
        limit = MISSED_STANCE_SWING_RATIO * float(np.nanmedian(swing))
        missed = (swing > limit) & (reason == "")
        reason = np.where(missed, [f"its swing lasts {x:.2f} s, more than {limit:.2f} s: a missed stance"
                                   for x in swing], reason)
    return reason


def _drop_implausible(strides: pd.DataFrame, foot: str) -> pd.DataFrame:
    reason = implausible(strides)
    for i in np.flatnonzero(reason != ""):
        t0, t1 = strides["t_start_s"].iloc[i], strides["t_end_s"].iloc[i]
        warn(f"{foot} foot IMU: the stride {t0:.2f}-{t1:.2f} s is dropped: {reason[i]}")
    return strides[reason == ""]


def foot_strides(rec: Recording, config: dict) -> pd.DataFrame | None:
    """Strides table (CONTRACT.md, `pdr.schema.STRIDE_COLUMNS`; ``source = "foot_imu"``) of the foot IMUs of ``rec``; None without a foot IMU.

    Extra columns: ``method``, ``heading_change_rad`` (the change of the stride direction since the previous stride of
    the same foot, from the foot INS; NaN for the first stride of a foot and for ``footstep_tracker``) and
    ``calibrated`` (the double-feet calibration was applied to the stride), ``t_swing_start_s, t_swing_end_s`` (when
    the foot moved); with the INS also ``dx_m, dy_m`` (the horizontal displacement in the foot's INS frame),
    ``lateral_std_m``, ``heading_rad`` and ``heading_change_std_rad`` (NaN for ``footstep_tracker``). Strides across
    clipped samples and implausible strides (:func:`implausible`) are dropped with a warning naming their time.
    """
    imus = foot_imus(rec)
    if not imus:
        return None
    section: dict[str, Any] = dict((config or {}).get("foot", {}))
    check_keys(section, sorted(SECTION_KEYS), "configuration [foot]")
    method = section.get("method", "zupt_ins")
    if method not in METHODS:
        raise InputError(f"configuration [foot]: expected method one of {', '.join(METHODS)}, found {method!r}")
    if "left" in imus and "right" in imus:
        check_pair(imus["left"], imus["right"])
    tables = []
    for foot, imu in sorted(imus.items()):
        t = imu["t_s"].to_numpy(float)
        rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 0.0
        if rate < MIN_RATE_HZ:
            warn(f"{foot} foot IMU: sampled at {rate:.1f} Hz, too slow to find the stances (need at least "
                 f"{MIN_RATE_HZ:g} Hz); no strides from this foot")
            continue
        saturated = _saturation(imu, foot)
        stance = ZeroVelocityDetection.from_config(section.get("zero_velocity")).detect(imu)
        algo = METHODS[method].from_config(section.get(method), foot=foot)
        strides = algo.estimate(imu, stance=stance).strides_
        if saturated.any() and len(strides):
            t = imu["t_s"].to_numpy()
            t_sat = t[saturated]
            hit = np.array([((t_sat >= a) & (t_sat <= b)).any()
                            for a, b in zip(strides["t_start_s"], strides["t_end_s"])])
            strides = strides[~hit]
        strides = _drop_implausible(strides, foot)
        extra = {c: strides[c] if c in strides else np.nan for c in ("heading_change_rad", *INS_COLUMNS)}
        tables.append(strides[[*STRIDE_COLUMNS, "t_swing_start_s", "t_swing_end_s"]].assign(method=method, **extra))
    if not tables:
        return empty_strides([*STRIDE_COLUMNS, "t_swing_start_s", "t_swing_end_s", "method", "heading_change_rad",
                              *INS_COLUMNS, "calibrated"])
    out = pd.concat(tables, ignore_index=True)
    out = out.sort_values("t_start_s", kind="stable").reset_index(drop=True)
    out["calibrated"] = False
    # double feet on the gaitmap strides: FootStep-Tracker 5.1 -> 4.7 cm MAE, the INS 2.2 -> 2.0 cm (off by default:
    # the INS strides of the two feet then stay each foot's own measure for the fusion's chain)
    if section.get("double_feet", method == "footstep_tracker") and out["foot"].nunique() == 2:
        cal = DoubleFeetCalibration.from_config(section.get("double_feet_calibration")).estimate(out)
        out = cal.strides_[out.columns]
    if len(out) == 0:
        warn("foot IMU: no stride found (the feet never rest, or fewer than two stances)")
    return out.reset_index(drop=True)


def foot_chain(strides: pd.DataFrame | None) -> tuple[pd.DataFrame, pd.DataFrame] | None:
    """The foot INS path as the fusion's chain of relative poses, and the strides left for range factors.

    Returns ``(steps, other)`` or None when no foot has INS strides (``heading_change_rad`` known). ``steps`` has one
    row per stride of the lead foot (the foot with the most INS strides; left on a tie), at its end (mid-stance):
    ``t_s``, ``step_length_m`` (horizontal displacement), ``step_length_std_m`` / ``lateral_std_m`` (along / across, from
    the INS covariance), ``heading_change_rad`` (change of the stride direction, the INS's heading change between
    stances), ``heading_change_std_rad`` (its yaw-error growth), ``heading_rad``, ``step_duration_s`` and
    ``displacement_measured`` (True: a stop inside the stride is no gap). Each row is a ``BetweenFactorPose2`` from the
    previous mid-stance: the pose's heading is the direction of the stride that ended there. A stride that does not
    start where the previous one ended (a dropped stride between them) spans the gap: it is a gap step (its heading
    change unknown). ``other`` holds the strides of other sources (a leg camera): the other foot's INS strides start
    and end half a stride away from the chain's mid-stances, so they are not range factors on it.
    """
    if strides is None or not len(strides) or "heading_change_rad" not in strides.columns:
        return None
    ins = strides[(strides["source"] == FOOT_SOURCE) & strides["dx_m"].notna()] if "dx_m" in strides.columns \
        else strides.iloc[:0]
    if not len(ins):
        return None
    counts = ins["foot"].value_counts()
    lead = sorted(counts.index[counts == counts.max()])[0]
    chain = ins[ins["foot"] == lead].sort_values("t_start_s", kind="stable")
    t0, t1 = chain["t_start_s"].to_numpy(float), chain["t_end_s"].to_numpy(float)
    joined = np.r_[True, np.abs(t0[1:] - t1[:-1]) < 1e-9]
    start = np.where(joined, t0, np.r_[t0[0], t1[:-1]])
    dtheta = chain["heading_change_rad"].to_numpy(float)
    dtheta = np.where(joined, dtheta, np.nan)
    steps = pd.DataFrame({
        "t_s": t1, "step_length_m": chain["length_m"].to_numpy(float),
        "step_length_std_m": chain["length_std_m"].to_numpy(float),
        "lateral_std_m": chain["lateral_std_m"].to_numpy(float),
        "heading_rad": chain["heading_rad"].to_numpy(float), "heading_change_rad": dtheta,
        "heading_change_std_rad": chain["heading_change_std_rad"].to_numpy(float),
        "step_duration_s": t1 - start, "displacement_measured": joined, "foot": lead,
    })
    return steps, strides.drop(index=ins.index)
